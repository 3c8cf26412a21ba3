"""A run killed outright (SIGKILL) leaves what ``rehabkit recover`` makes a run folder: the recording renamed and
read by the Rerun SDK, the bag rewritten whole and read by rosbags, the safety log audited up to its last record, a
summary from what the recording holds, marked ``killed (recovered)``; a run over the folder before that is refused."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import SCENARIOS


def _killed_run(out: Path) -> None:
    """The HIT round trip for 300 s with its bag, killed once its recording holds its first columns and its bag its
    first chunk (polled)."""
    proc = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "run", str(SCENARIOS / "hit_roundtrip.yaml"),
                             "--out", str(out), "--bag", "--set", "duration=300"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    deadline = time.monotonic() + 120
    tmp, part = out / "run.rrd.tmp", out / ".run.mcap.part"

    def written() -> bool:  # the recording's first columns and the bag's first chunk on disk
        return tmp.exists() and tmp.stat().st_size > 200_000 and part.exists() and part.stat().st_size > 50_000

    while not written() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)  # (polling a file the run writes, with a deadline: not a synchronisation by sleeping)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL


def test_a_killed_runs_folder_is_recovered(tmp_path):
    from rehabkit.cli.main import main

    out = tmp_path / "run"
    _killed_run(out)
    # (the scenario as it ran is written as the session opens: a killed run keeps it, and replays from it)
    assert {"run.rrd.tmp", ".run.mcap.part", "safety_log.jsonl", "scenario.yaml"} <= {p.name for p in out.iterdir()}
    assert main(["run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(out)]) == 2  # (it would overwrite it)
    assert main(["recover", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == {"run.rrd", "run.mcap", "safety_log.jsonl", "summary.json",
                                                "scenario.yaml"}
    summary = json.loads((out / "summary.json").read_text())
    # listed as a finished run's summary lists them: its name, its files, its bag, the log's last hash
    assert summary["name"] == "hit-roundtrip"
    assert summary["outputs"] == {"rrd": "run.rrd", "safety_log": "safety_log.jsonl", "scenario": "scenario.yaml"}
    assert summary["bag"]["topics"]["/joint_states"]["type"] == "sensor_msgs/msg/JointState"
    last = json.loads((out / "safety_log.jsonl").read_text().splitlines()[-1])
    assert summary["safety_log_hash"] == last["hash"]
    # the recording given the footer a killed run's file lacks: Rerun's own check passes it (its CLI through
    # rerun_cli, which starts the same binary as `python -m rerun` without importing the SDK first: ~0.5 s of CPU)
    verified = subprocess.run([sys.executable, "-m", "rerun_cli", "rrd", "verify", str(out / "run.rrd")],
                              capture_output=True, text=True)
    assert verified.returncode == 0, verified.stderr
    assert summary["ended"]["how"] == "killed (recovered)" and not summary["passed"]
    recovered = summary["recovered"]
    assert 0.5 < recovered["recording_until_s"] == summary["metrics"]["sim_time_s"] < 300.0  # (where the kill fell)
    assert summary["metrics"]["tracking_rms_deg"] < 0.01  # (the HIT tracks its plan to a thousandth of a degree)
    with AnyReader([out / "run.mcap"]) as bag:  # the bag whole again: rosbags reads it, up to the kill
        stamps = [stamp for _, stamp, _ in bag.messages()]
        assert len(stamps) == sum(recovered["bag_messages"].values()) > 100
        # the trace's topics stream as the run goes (they were written at the finish only: a killed run had none)
        joints = [c for c in bag.connections if c.topic == "/joint_states"]
        states = [stamp for _, stamp, _ in bag.messages(connections=joints)]
    assert len(states) == recovered["bag_messages"]["/joint_states"] > 500
    assert recovered["bag_messages"]["/targets/pose"] >= 1  # (the first leg's goal, as it began: streamed too)
    assert np.all(np.diff(states) == 1_000_000)  # (every control step, none lost between the chunks)
    assert main(["audit", str(out)]) == 0
    assert main(["recover", str(out)]) == 2  # (nothing left to recover)
    assert main(["recover", str(tmp_path / "elsewhere")]) == 2  # (no such folder: said so)


def test_validate_and_run_say_the_folder_holds_a_killed_run_not_recovered(tmp_path, capsys):
    from rehabkit.cli import exits
    from rehabkit.cli.main import main

    scenario = str(SCENARIOS / "hit_roundtrip.yaml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "run.rrd.tmp").write_bytes(b"")  # (what a killed run leaves: its recording as it was being written)
    (out / ".run.mcap.part").write_bytes(b"")
    assert main(["validate", scenario, "--out", str(out)]) == 0  # (the scenario is fine: said, not refused)
    said = capsys.readouterr().out.splitlines()
    warning = next(line for line in said if line.strip().startswith("WARNING"))
    assert str(out) in warning and f"`rehabkit recover {out}`" in warning
    assert "run.rrd.tmp" in warning and ".run.mcap.part" in warning
    assert main(["run", scenario, "--out", str(out)]) == 2  # refused: the leftovers kept
    refused = exits.last_refusal
    assert refused.code == "out-killed-run" and refused.option == "--out"
    assert capsys.readouterr().err.splitlines() == [refused.message]  # (said once, as that refusal)
    assert {p.name for p in out.iterdir()} == {"run.rrd.tmp", ".run.mcap.part"}
    (out / "run.rrd.tmp").unlink()
    (out / ".run.mcap.part").unlink()
    assert main(["validate", scenario, "--out", str(out)]) == 0
    assert "WARNING" not in capsys.readouterr().out


def test_a_killed_run_without_a_bag_is_recovered_and_replays_from_its_folder(tmp_path, capsys):
    """A killed run that kept no bag (made here from a finished 0.3 s run: its recording as the loop left it, its
    scenario, its log without the closing record): recovered (its plugins listed as a finished run's summary lists
    them), and ``rehabkit replay`` runs it again from the folder — the scenario as it ran is written as the session
    opens. (Recover's report read the bag's figures it did not have, and replay had no scenario to start from.)"""
    from rehabkit.cli.main import main

    done, killed = tmp_path / "done", tmp_path / "killed"
    run = ["run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(done), "--set", "duration=0.3"]
    assert main(run) == 1  # (its task unfinished)
    killed.mkdir()
    (killed / "run.rrd.tmp").write_bytes((done / "run.rrd").read_bytes())
    (killed / "scenario.yaml").write_text((done / "scenario.yaml").read_text())
    lines = (done / "safety_log.jsonl").read_text().splitlines(keepends=True)
    (killed / "safety_log.jsonl").write_text("".join(lines[:-1]))  # (no closing record: the process died)
    capsys.readouterr()
    assert main(["recover", str(killed)]) == 0
    summary = json.loads((killed / "summary.json").read_text())
    finished = json.loads((done / "summary.json").read_text())
    assert "bag" not in summary and summary["plugins"] == finished["plugins"]
    assert summary["recovered"]["recording_until_s"] == pytest.approx(0.299, abs=0.002)
    assert main(["replay", str(killed), "--set", "duration=0.3"]) == 1  # (ran: its task unfinished again)


def test_a_recording_torn_mid_message_is_cut_after_its_last_whole_one(tmp_path, capsys):
    """A kill during the recording's write leaves its last message torn, which Rerun's reader refuses whole ("payload
    exceeds file size"; a CI run's kill fell there). Made here from a finished 2 s run's recording cut at 60 %: Rerun
    itself refuses the cut file; recovered, it holds every message before the torn one, the summary says one was
    left out, and ``rerun rrd verify`` passes it."""
    from rerun.chunk import RrdReader

    from rehabkit.cli.main import main

    done, killed = tmp_path / "done", tmp_path / "killed"
    assert main(["run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(done), "--set", "duration=2.0"]) == 0
    killed.mkdir()
    whole = (done / "run.rrd").read_bytes()
    (killed / "run.rrd.tmp").write_bytes(whole[: int(len(whole) * 0.6)])
    (killed / "scenario.yaml").write_text((done / "scenario.yaml").read_text())
    with pytest.raises(Exception, match="exceeds file size"):  # (Rerun's own reader: the premise, in its words)
        RrdReader(str(killed / "run.rrd.tmp")).stream().to_chunks()
    capsys.readouterr()
    assert main(["recover", str(killed)]) == 0
    summary = json.loads((killed / "summary.json").read_text())
    assert summary["outputs"]["rrd"] == "run.rrd" and not (killed / "run.rrd.tmp").exists()
    torn = summary["recovered"]["recording_torn_bytes"]  # (said in words beside it, for a person)
    assert 0 < torn < int(len(whole) * 0.6) and 0.0 < summary["recovered"]["recording_until_s"] < 2.0
    verified = subprocess.run([sys.executable, "-m", "rerun_cli", "rrd", "verify", str(killed / "run.rrd")],
                              capture_output=True, text=True)
    assert verified.returncode == 0, verified.stderr
