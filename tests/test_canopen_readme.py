"""The README's "On CANopen drives" section, run as written: its commands, the lab robot's wiring (validated, since
the lab's bus is not here) and the two-process run in a network namespace of its own."""

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from rehabkit.canopen.bus.drive_dictionary import read_dictionary
from rehabkit.canopen.bus.pdo_layout import needed
from rehabkit.canopen.bus.pdo_plan import PdoPlanError, plan_pdos
from tests.canopen_runs import SHARED, cli_run
from tests.conftest import FIRST_ROUND_TRIP, ROOT
from tests.located import located
from tests.test_cli import cli

README = (ROOT / "README.md").read_text()
SECTION = README[README.index("## On CANopen drives"):README.index("## Benchmarks")]
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", SECTION, re.S)


@pytest.mark.xdist_group(SHARED)
def test_the_canopen_commands_run_as_written(request):
    validate, run = (c.split("#")[0].strip() for c in BLOCKS[0][1].strip().splitlines())
    refused = cli(*shlex.split(validate)[1:], cwd=ROOT)
    # refused at the control rate (what it says there, and its fix: tests/test_canopen_setup.py)
    assert (refused.returncode, located(refused.stderr)) == (2, [("scenarios/hit_roundtrip.yaml", 37, 9,
                                                                  "rates.control_hz")]), refused.stderr
    # the command run as written (with --out), once: tests/test_canopen_backend.py's tracking test reads it too
    shared = cli_run(request, *shlex.split(run)[1:])
    done = shared.done
    assert done.returncode == 0, done.stderr
    summary = json.loads((shared.out / "summary.json").read_text())
    assert summary["metrics"]["can_cycles"] == 4250 and summary["metrics"]["can_emcy"] == 0
    frames = shared.frames  # (can.LogReader on its can.asc, as the README says to read it)
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
    assert bad.returncode == 2 and [(Path(f).name, n, at) for f, n, _, at in located(bad.stderr)] == [
        ("lab_can.yaml", line, "backend.drives.4.eds")], bad.stderr
    d = read_dictionary(tmp_path / "drives" / "wrist.eds", 5)  # what it names: the object the file lacks
    with pytest.raises(PdoPlanError) as lacking:  # (the drive's default mode, cst: its target torque in an RPDO)
        plan_pdos(d, 5, *needed(d, "cst"))
    assert lacking.value.index == 0x6071 and (0x6071, 0) not in d.objects


@pytest.mark.realtime
@pytest.mark.xdist_group("realtime")
def test_simulated_drives_in_another_process_as_the_readme_runs_them(tmp_path):
    """``rehabkit drives`` and the run in a network namespace of their own, over udp_multicast, in real time: the
    host waits for the drives to answer, runs its cycles against them (HIT's first round trip, tests/conftest.py's
    FIRST_ROUND_TRIP given as --set) and writes its summary; then the drives it leaves behind are listened to for
    0.3 s (tests/listen_can.py, in the same namespace) before they are stopped.

    Only what holds under any load is asserted (this 2-core VM busy with the other tests stalls a process for tens of
    ms at times): the run ends safe, completed (exit 0, every cycle) or stopped for one of the reasons a stalled
    host or drives' process gives — the drives' SYNC or heartbeat watch (EMCY 0x8100, 0x8130: a drive's quick stop),
    TPDOs or a drive's heartbeat that came late (at the start: its statusword late for the 402 walk), the tracking
    after holds through late steps (velocity, position) — exit 1; and however it ended, the drives raise no EMCY
    after it (none on the bus afterwards; none sent at all where the run completed), each in pre-operational
    (heartbeat 0x7F). How often it completes: benchmarks/canopen_two_process.py."""
    command = BLOCKS[2][1].strip()
    assert command.startswith("unshare -n sh -c '") and command.endswith("RC=$?; kill $!; exit $RC'")
    out = tmp_path / "run"
    listen = f"{sys.executable} {ROOT / 'tests' / 'listen_can.py'} udp_multicast 239.74.163.2 0.3"
    # the first round trip only (A → B → A, 4.5 s of the wall clock, not 8.5): the two processes, the drives' answer,
    # the paced cycles, a run that completes and what it leaves behind are all there by then; the second round trip
    # is the first again. (Flow YAML in double quotes: the command is already in single ones.)
    first = " ".join(f'--set "{k}={yaml.safe_dump([v], default_flow_style=True, width=1000).strip()[1:-1]}"'
                     for k, v in FIRST_ROUND_TRIP.items())
    command = command.replace("; RC=$?; kill $!;", f" {first} --out {out}; RC=$?; {listen}; kill $!; wait $!;")
    done = subprocess.run(command, shell=True, cwd=ROOT, capture_output=True, text=True, timeout=120)
    # 0 completed, 1 a safety stop, 4 a backend fault (the drives' own stop: exit 4 wherever the first trip is the
    # backend's, README: 'Stopping and the e-stop')
    assert done.returncode in (0, 1, 4), done.stderr
    summary = json.loads((out / "summary.json").read_text())
    metrics, events = summary["metrics"], summary["safety"]["events"]
    assert metrics["can_cycles"] > 0 and metrics["can_latency_median_ms"] > 0  # (its figures: canopen_loop.py)
    if done.returncode == 0:
        assert metrics["can_cycles"] == 2250 and not events  # (4.5 s at 500 Hz)
    else:
        rule, data = events[0]["rule"], events[0]["data"]
        assert rule != "backend" or done.returncode == 4, events[0]  # (a backend's first trip: a backend fault)
        cause, state = data.get("cause"), data.get("state")
        assert rule in ("velocity", "position") or rule == "backend" and (  # (the drives' faults a loaded VM meets)
            cause == "emcy" and data["error_code"] in (0x8100, 0x8130) or cause in ("no-tpdo", "bus-silent",
            "heartbeat-lost") or cause == "left-operation-enabled" and state == "QUICK_STOP_ACTIVE"
            or cause == "not-operation-enabled" and state in ("READY_TO_SWITCH_ON", "SWITCHED_ON",
                                                              "SWITCH_ON_DISABLED")), events[0]
    after = json.loads(done.stdout.strip().splitlines()[-1])  # (the listener's: from its start, ~0.2 s after)
    assert after["emcy"] == [] and after["heartbeats"] == {str(n): [0x7F] for n in range(1, 7)}, after
    drives = re.search(r"drives: \d+ cycles.*", done.stderr)[0]  # (their own figures, as they end)
    # (a completed run: none at all, ever; a stopped one's (exit 1, or 4 where the drives' EMCY was the first trip) are
    # those of its stop, and none came after it, above)
    assert "EMCYs sent" not in drives or done.returncode != 0, drives
