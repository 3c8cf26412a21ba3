"""However a run on hardware ends — SIGTERM, Ctrl-C, a second Ctrl-C while the robot stops or while the hardware is
released — the robot is brought to rest in the run's stop category first, then the files are written, then the
hardware is released as at a normal end. On CiA 402 drives (simulated, on a lock-step virtual bus) that is read back
from the CAN trace by python-can and decoded with canopen's own tables, not rehabkit's: the quick stop, every drive
SWITCH ON DISABLED, its watch of the host's heartbeat off (0x1016), NMT pre-operational, then silence. Over the link:
the robot at rest in the bridge's last state, the bridge not holding on its own, its process gone — and a terminal's
Ctrl-C reaches the host alone (the bridge it started is in a session of its own)."""

from __future__ import annotations

import json
import os
import signal

import can
import numpy as np
import pytest
from canopen.nmt import NMT_COMMANDS
from canopen.profiles.p402 import State402

import rehabkit.canopen.backend as canopen_backend
import rehabkit.hardware.backend as link_backend
from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.hardware.link.protocol import HOLDING
from tests.conftest import SCENARIOS

NODES = range(1, 7)  # the HIT's six drives
BACKENDS = {  # the backend's class, the scenario's overrides, the control period [s], what releases the hardware
    "canopen": (canopen_backend.CanopenBackend, {"backend": {"type": "canopen", "clock": "lockstep"},
                                                 "rates": {"control_hz": 500}, "duration": 1.5}, 0.002,
                "bring_to_rest"),  # (the drives' own end: quick stop, power off, 0x1016 off, NMT)
    "hardware": (link_backend.HardwareBackend, {"backend": {"type": "hardware", "clock": "lockstep"},
                                                "duration": 1.5}, 0.001, "stop_bridge"),
}
CUT_S = 0.4  # mid-motion on the HIT round trip
EXITS = {"SIGTERM": 143, "SIGINT": 130}
# (the first signal, a second one, when the second comes: during the host's stop of the robot, or while the backend
# releases the hardware)
ENDINGS = [("SIGTERM", None, None), ("SIGINT", "SIGINT", "stop"), ("SIGTERM", "SIGINT", "release")]
IDS = ["sigterm", "ctrl-c-twice-mid-stop", "sigterm-then-ctrl-c-mid-release"]


def _as_a_terminal_sends(backend, name: str) -> list[int]:
    """The processes a signal reaches: SIGTERM (a service manager's kill) this one; SIGINT (Ctrl-C in a terminal)
    its whole process group — a bridge this run started among it if it shares the group."""
    pids = [os.getpid()]
    bridge = getattr(backend, "process", None)
    if name == "SIGINT" and bridge is not None and os.getpgid(bridge.pid) == os.getpgrp():
        pids.insert(0, bridge.pid)
    return pids


def _run_cut(tmp_path, monkeypatch, kind, first, again=None, when=None):
    """The HIT round trip on ``kind`` with signal ``first`` as the backend's step reaches ``CUT_S``, and ``again``
    at the host stop's first step (``when='stop'``) or as the backend starts to release the hardware (``'release'``)."""
    cls, over, dt, releases = BACKENDS[kind]
    module = canopen_backend if kind == "canopen" else link_backend
    real_step, real_release = cls.step, getattr(module, releases)
    cut = round(CUT_S / dt)
    seen = {"steps": 0, "sessions": None}

    def send(backend, name):
        for pid in _as_a_terminal_sends(backend, name):
            os.kill(pid, getattr(signal, name))

    def step(self, n=1):
        seen["steps"] += 1
        if seen["steps"] == cut:
            if getattr(self, "process", None) is not None:
                seen["sessions"] = (os.getsid(self.process.pid), os.getsid(0))
            send(self, first)
        if when == "stop" and seen["steps"] == cut + 1:
            send(self, again)
        real_step(self, n)

    def release(*args, **kwargs):
        if when == "release":
            os.kill(os.getpid(), getattr(signal, again))
        return real_release(*args, **kwargs)

    monkeypatch.setattr(cls, "step", step)
    monkeypatch.setattr(module, releases, release)
    runner = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", over), out_dir=tmp_path / "run")
    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)  # (another library's, maybe: Ray's)
    try:
        result = runner.run()
    except KeyboardInterrupt as exc:  # (a failure, not pytest's own Ctrl-C)
        pytest.fail(f"{type(exc).__name__} out of the run: the hardware's release was cut short")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    # ended as interrupted by the first signal, the safety layer's 'interrupt' in the run's stop category, at rest
    assert summary["ended"]["how"] == "interrupted" and summary["ended"]["signal"] == first
    assert result.exit_code == EXITS[first]
    (event,) = summary["safety"]["events"]
    assert event["rule"] == "interrupt" and event["t"] == pytest.approx((cut - 1) * dt, abs=2 * dt)
    assert event["data"]["category"] == runner.sc.safety.category_of("interrupt")
    qd = result.trace.qd
    assert np.abs(qd[cut - 2]).max() > np.radians(5.0), "not moving when cut: nothing to bring to rest"
    assert np.abs(qd[-1]).max() < np.radians(1.0)
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers  # the process's back
    return runner, summary, seen


def _statusword_state(word: int) -> str:
    """A CiA 402 statusword's state, by canopen's own masks."""
    return next(name for name, (mask, value) in State402.SW_MASK.items() if word & mask == value)


@pytest.mark.parametrize("first, again, when", ENDINGS, ids=IDS)
def test_canopen_a_signal_stops_the_robot_then_every_drive_is_left_disabled_and_pre_operational(
        tmp_path, monkeypatch, first, again, when):
    runner, summary, _ = _run_cut(tmp_path, monkeypatch, "canopen", first, again, when)
    assert summary["outputs"]["can_trace"] == "can.asc"
    frames = list(can.LogReader(tmp_path / "run" / "can.asc"))
    enabled = max(k for k, f in enumerate(frames) if f.arbitration_id == 0x201 and f.data[0] == 0x0F)
    tail = frames[enabled + 1 :]  # from the last 'enable operation' on: the end
    # the drives' own stop (quick stop), then the power stages off (disable voltage), as at a normal end
    controlwords = [f.data[0] for f in tail if f.arbitration_id == 0x201]
    assert controlwords[0] == 0x02 and controlwords[-1] == 0x00 and set(controlwords) == {0x02, 0x00}
    last_status = {n: _statusword_state(int.from_bytes(f.data[:2], "little"))
                   for f in frames for n in NODES if f.arbitration_id == 0x180 + n}
    assert last_status == dict.fromkeys(NODES, "SWITCH ON DISABLED")
    # each drive's heartbeat consumer of the host off (SDO download 0x1016 sub 1 = 0), confirmed
    for n in NODES:
        asked = [f for f in tail if f.arbitration_id == 0x600 + n]
        assert [bytes(f.data) for f in asked] == [bytes([0x23, 0x16, 0x10, 0x01, 0, 0, 0, 0])]
        assert [f.data[0] for f in tail if f.arbitration_id == 0x580 + n] == [0x60]
    # the last NMT command to each node: pre-operational; then nothing from the drives but heartbeats
    commands = {code: name for name, code in NMT_COMMANDS.items()}
    nmt = {f.data[1]: commands[f.data[0]] for f in frames if f.arbitration_id == 0x000}
    assert nmt == dict.fromkeys(NODES, "PRE-OPERATIONAL")
    last_nmt = max(k for k, f in enumerate(frames) if f.arbitration_id == 0x000)
    assert not [f for f in frames[last_nmt + 1 :] if f.arbitration_id < 0x700]
    # and as the simulated drives hold it themselves
    drives = runner.setup.backend.rig.drives
    assert [d.machine.state.name for d in drives] == ["SWITCH_ON_DISABLED"] * 6
    assert [d.nmt.state for d in drives] == ["PRE-OPERATIONAL"] * 6


@pytest.mark.parametrize("first, again, when", ENDINGS, ids=IDS)
def test_link_a_signal_stops_the_robot_then_the_bridge_is_gone(tmp_path, monkeypatch, first, again, when):
    runner, summary, seen = _run_cut(tmp_path, monkeypatch, "hardware", first, again, when)
    backend = runner.setup.backend
    host_session, bridge_session = seen["sessions"][1], seen["sessions"][0]
    assert bridge_session != host_session  # (a terminal's Ctrl-C reaches the host alone: it stops the robot)
    # the bridge's last state: the robot at rest, the bridge still taking the host's commands (not holding on its own)
    assert np.abs(backend.qd).max() < np.radians(1.0)
    assert not backend.status & HOLDING
    assert backend.process.poll() is not None  # the bridge this run started: stopped, as at a normal end


def test_ctrl_c_in_a_serial_sweep_records_the_run_as_interrupted_stops_and_a_resume_runs_it_again(tmp_path,
                                                                                                monkeypatch):
    """Ctrl-C during a sweep's second run: that run is brought to rest and recorded as interrupted, the sweep stops
    (no third run), and resuming keeps the first run and runs the interrupted one again. (kill -9: test_sweep.py.)"""
    from rehabkit.sim.mujoco import MujocoBackend
    from rehabkit.sweep.engine import run_sweep

    real, steps = MujocoBackend.step, {"n": 0}

    def step(self, n=1):
        steps["n"] += 1
        if steps["n"] == 2000 + 400:  # 0.4 s into the second run (2 s each at 1 kHz)
            os.kill(os.getpid(), signal.SIGINT)
        real(self, n)

    monkeypatch.setattr(MujocoBackend, "step", step)
    out = tmp_path / "sweep"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(SCENARIOS / "hit_roundtrip.yaml", None, 3, out, serial=True, overrides=["duration=2"])
    rows = {f.stem: json.loads(f.read_text()) for f in (out / "runs").glob("*.json")}
    ended = sorted((r["ended"]["how"], r["ended"].get("signal"), r["error"]) for r in rows.values())
    assert ended == [("completed", None, None), ("interrupted", "SIGINT", "interrupted (SIGINT) at t=0.399 s")]
    monkeypatch.setattr(MujocoBackend, "step", real)
    resumed = run_sweep(SCENARIOS / "hit_roundtrip.yaml", None, 3, out, serial=True, overrides=["duration=2"])
    assert (resumed.skipped, resumed.executed) == (1, 2) and not resumed.failed
