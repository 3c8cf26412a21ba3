"""However a run ends, it leaves a folder that says how: Ctrl-C, SIGTERM and an error out of the loop bring the robot
to rest through the safety layer first (a second Ctrl-C does not cut that short), then the recording, the safety log,
the scenario and ``summary.json`` (``ended``) are written whole, judged on what the run reached."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from rehabkit.cli.audit import cmd_audit
from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.sim.mujoco import MujocoBackend
from tests.conftest import SCENARIOS

CUT_AT = 400  # the control step (1 kHz) at which each ending below happens: 0.4 s into the HIT round trip


def _run_cut(tmp_path, monkeypatch, cut, then=None):
    """The HIT round trip (2 s) with ``cut()`` called as the backend steps at ``CUT_AT``, and ``then()`` once, one step
    after it (while the robot is being brought to rest)."""
    real = MujocoBackend.step
    steps = {"n": 0}

    def step(self, n=1):
        steps["n"] += 1
        if steps["n"] == CUT_AT:
            cut()
        if then is not None and steps["n"] == CUT_AT + 1:
            then()
        real(self, n)

    monkeypatch.setattr(MujocoBackend, "step", step)
    runner = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", {"duration": 2.0}), out_dir=tmp_path / "run")
    return runner, runner.run()


def _written(out) -> dict:
    summary = json.loads((out / "summary.json").read_text())
    assert {p.name for p in out.iterdir()} == {"summary.json", "run.rrd", "scenario.yaml", "safety_log.jsonl"}
    return summary


def test_ctrl_c_brings_the_robot_to_rest_then_writes_every_file(tmp_path, monkeypatch):
    def interrupt():
        raise KeyboardInterrupt

    runner, result = _run_cut(tmp_path, monkeypatch, interrupt)
    summary = _written(tmp_path / "run")
    assert summary["ended"] == {"how": "interrupted", "reason": "Ctrl-C (SIGINT)", "t": 0.399, "signal": "SIGINT"}
    assert result.exit_code == 130 and not result.passed
    (event,) = summary["safety"]["events"]
    assert (event["rule"], event["t"]) == ("interrupt", 0.399)
    # brought to rest by the stop (category 2 on the HIT: a controlled stop, then held) before the run ended
    qd = result.trace.qd
    assert np.abs(qd[-1]).max() < np.radians(1.0) < np.abs(qd[CUT_AT - 1]).max()
    assert summary["metrics"]["sim_time_s"] < 2.0 - 0.5
    # what the run met before it was cut short is said not reached, not passed
    assert summary["expectations"] and all(not v["passed"] for v in summary["expectations"])
    assert any(v.get("reason", "").startswith("not reached") for v in summary["expectations"])
    assert cmd_audit(type("A", (), {"run_dir": str(tmp_path / "run")})()) == 0


def test_sigterm_ends_the_run_as_ctrl_c_does_and_a_second_ctrl_c_does_not_cut_the_stop_short(tmp_path, monkeypatch):
    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)  # (another library's, maybe: Ray's)
    runner, result = _run_cut(tmp_path, monkeypatch, lambda: os.kill(os.getpid(), signal.SIGTERM),
                              then=lambda: os.kill(os.getpid(), signal.SIGINT))
    summary = _written(tmp_path / "run")
    assert summary["ended"]["how"] == "interrupted" and summary["ended"]["signal"] == "SIGTERM"
    assert result.exit_code == 143
    assert np.abs(result.trace.qd[-1]).max() < np.radians(1.0)  # (the second Ctrl-C, mid-stop, was held off)
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers  # the process's again


def test_an_error_out_of_the_loop_is_a_plugin_fault_with_the_robot_at_rest(tmp_path, monkeypatch):
    def fault():
        raise ZeroDivisionError("the patient model divided by zero")

    runner, result = _run_cut(tmp_path, monkeypatch, fault)
    summary = _written(tmp_path / "run")
    assert summary["ended"]["how"] == "plugin-fault" and summary["ended"]["error_type"] == "ZeroDivisionError"
    assert result.exit_code == 3
    assert [e["rule"] for e in summary["safety"]["events"]] == ["plugin-error"]
    assert np.abs(result.trace.qd[-1]).max() < np.radians(1.0)


@pytest.mark.parametrize("how, code", [("completed", 0), ("stopped", 1), ("plugin-fault", 3), ("backend-fault", 4)])
def test_each_ending_has_its_exit_code(how, code):
    from rehabkit.core.results.ending import RunEnding

    assert RunEnding(how).exit_code(passed=True) == code


def test_sigterm_during_the_bags_write_is_taken_after_it_and_the_bag_reads_whole(tmp_path, monkeypatch):
    """SIGTERM sent while the bag writes a message (the 600th, 0.3 s in): the message is written whole and the run ends
    as SIGTERM ends it — the bag reads, every control step's joint state up to the end. (Raised inside the mcap
    writer, it tore that record: the rest of its chunk unreadable by rosbags.)"""
    from mcap.writer import Writer
    from rosbags.highlevel import AnyReader

    real, calls = Writer.add_message, {"n": 0}

    def add_message(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 600:
            os.kill(os.getpid(), signal.SIGTERM)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Writer, "add_message", add_message)
    out = tmp_path / "run"
    result = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", {"duration": 1.0, "ros": {"bag": True}}),
                    out_dir=out).run()
    assert result.summary["ended"]["signal"] == "SIGTERM" and result.exit_code == 143
    with AnyReader([out / "run.mcap"]) as bag:
        joints = [c for c in bag.connections if c.topic == "/joint_states"]
        stamps = np.array([stamp for _, stamp, _ in bag.messages(connections=joints)])
    assert len(stamps) == len(result.trace.t) and set(np.diff(stamps)) == {1_000_000}
