"""The README's "On CANopen drives" section, run as written: its commands, the lab robot's wiring (validated, since
the lab's bus is not here) and the two-process run in a network namespace of its own."""

import json
import re
import shlex
import shutil
import subprocess

import can
import pytest

from tests.conftest import ROOT
from tests.test_cli import cli

README = (ROOT / "README.md").read_text()
SECTION = README[README.index("## On CANopen drives"):README.index("## Benchmarks")]
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", SECTION, re.S)


def test_the_canopen_commands_run_as_written(tmp_path):
    validate, run = (c.split("#")[0].strip() for c in BLOCKS[0][1].strip().splitlines())
    refused = cli(*shlex.split(validate)[1:], cwd=ROOT)
    assert refused.returncode == 2
    assert "scenarios/hit_roundtrip.yaml:37:9: rates.control_hz: backend 'canopen': the CAN bus cannot carry 6 " \
           "drives at 1000 Hz" in refused.stderr and "the bus carries up to 518 Hz" in refused.stderr
    done = cli(*shlex.split(run)[1:], "--out", str(tmp_path / "run"), cwd=ROOT)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["metrics"]["can_cycles"] == 4250 and summary["metrics"]["can_emcy"] == 0
    frames = list(can.LogReader(tmp_path / "run" / "can.asc"))  # (as the README says to read it)
    assert len(frames) > 4250 * 19 and 4250 + 8 <= sum(f.arbitration_id == 0x80 for f in frames) < 4250 + 8 + 100


def test_the_lab_robots_wiring_validates_and_its_mistakes_are_located(tmp_path):
    """The lab's six drives, as the README writes them (their wrist EDS a copy of the generic servo's), validate; a
    drive's EDS without the objects the backend needs is refused at its line, naming them."""
    lang, text = BLOCKS[1]
    assert lang == "yaml"
    (tmp_path / "drives").mkdir()
    shutil.copy(ROOT / "rehabkit" / "canopen" / "eds" / "cia402_servo.eds", tmp_path / "drives" / "wrist.eds")
    (tmp_path / "lab_can.yaml").write_text(text.replace("scenarios/", f"{ROOT}/scenarios/"))
    ok = cli("validate", "lab_can.yaml", cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr
    eds = (tmp_path / "drives" / "wrist.eds").read_text()
    (tmp_path / "drives" / "wrist.eds").write_text(eds.replace("[6071]", "[6F71]"))  # no target torque
    bad = cli("validate", "lab_can.yaml", cwd=tmp_path)
    line = next(i for i, x in enumerate(text.splitlines(), 1) if "drives/wrist.eds" in x)
    assert bad.returncode == 2 and f"lab_can.yaml:{line}:" in bad.stderr
    assert "backend.drives.4.eds" in bad.stderr and "wrist.eds has no 0x6071 (target torque): the run maps it " \
        "into an RPDO every cycle" in bad.stderr


@pytest.mark.realtime
@pytest.mark.xdist_group("realtime")
def test_simulated_drives_in_another_process_as_the_readme_runs_them(tmp_path):
    """``rehabkit drives`` and the run in a network namespace of their own, over udp_multicast, in real time: the
    host waits for the drives to answer and runs its cycles against them, and writes its summary. On this 2-core VM
    busy with the other tests a process is at times stalled longer than the drives' SYNC watchdog (10 ms): the
    drives then quick stop and say why (EMCY 0x8100), and the run stops with that reason (exit 1), or the holds
    through late steps cost the tracking its expectation (exit 1): the safety chain working, not the test failing."""
    command = BLOCKS[2][1].strip()
    assert command.startswith("unshare -n sh -c '") and command.endswith("RC=$?; kill $!; exit $RC'")
    out = tmp_path / "run"
    done = subprocess.run(command.replace("; RC=$?", f" --out {out}; RC=$?"), shell=True, cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, 1), done.stderr
    summary = json.loads((out / "summary.json").read_text())
    metrics, events = summary["metrics"], summary["safety"]["events"]
    assert metrics["can_cycles"] > 0 and metrics["can_latency_median_ms"] > 0  # (its figures: canopen_loop.py)
    assert metrics["can_cycles"] == 4250 if not events else events[0]["rule"] in ("backend", "velocity", "position")
