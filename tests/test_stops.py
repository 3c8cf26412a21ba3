"""Stop categories (IEC 60204-1) and the latched e-stop (ISO 13850): what each category sends, what a stop takes on
HIT at its top planned speed, in simulation and over the link, and an e-stop that outlives the session."""

from __future__ import annotations

import json
import os
import tempfile
import threading
import time
from contextlib import contextmanager, suppress
from pathlib import Path

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.cli import main
from rehabkit.cli.run_report import run_report
from rehabkit.core.kinds.backend import EStopLatchedError
from rehabkit.core.safety.estop import EStopLatch, own_state
from rehabkit.core.safety.layer import SafetyLayer
from rehabkit.core.scenario.safety import SafetyConfig
from rehabkit.core.setup.errors import SetupError
from tests.conftest import SCENARIOS, checked
from tests.located import refusal, suggested

ESTOP = SCENARIOS / "safety" / "hit_estop.yaml"
LINK = {"backend": {"type": "hardware", "clock": "lockstep"}}


def _layer(hit, category: int) -> SafetyLayer:
    return SafetyLayer(hit.model, SafetyConfig(stop_category={"default": category}, stop_decel_deg_s2=360),
                       gravity=hit.gravity_torque)


@pytest.mark.parametrize("category", [0, 1, 2])
def test_each_category_sends_what_it_says(hit, category):
    lim = hit.model.limits
    q0, v0 = (lim.lower + lim.upper) / 2, np.radians([0, 45, 0, 0, 0, 0])
    layer = _layer(hit, category)
    layer.trip(1.0, q0, "plan", "test", qd=v0)
    ramp = np.radians(45) / np.radians(360)  # the fastest joint's speed over the deceleration bound: 0.125 s
    mid = checked(layer, 1.0 + ramp / 2, q0 + v0 * ramp / 2, v0 / 2, np.full(6, 5.0))  # (the controller is ignored)
    after = checked(layer, 1.0 + ramp + 0.01, q0 + v0 * ramp / 2, np.zeros(6), np.full(6, 5.0))
    g = hit.gravity_torque(q0 + v0 * ramp / 2)
    if category == 0:
        assert not mid.any() and not after.any() and layer.torque_off
    else:  # on the ramp: gravity plus the torque decelerating the joint (negative on the moving one)
        assert mid[1] < g[1] and np.allclose(np.delete(mid - g, 1), 0, atol=1.0)
        if category == 1:
            assert not after.any() and layer.torque_off
        else:  # held where the ramp ended, against gravity
            assert np.allclose(after, g, atol=1e-6) and not layer.torque_off
    assert layer.events[0].data["category"] == category


def test_a_stop_category_for_an_unknown_rule_is_refused_where_written():
    (d,) = refusal(ESTOP, "safety.stop_category.estop=1").diagnostics
    assert (d.mark.file, d.path) == ("<--set safety.stop_category.estop>", "safety.stop_category.estop")
    assert d.fix == "did you mean 'e-stop'?"


def _stop(category: int, link: bool = False) -> dict:
    with own_state(Path(tempfile.mkdtemp())):  # each its own e-stop latch
        r = run_scenario(ESTOP, {"safety.stop_category.e-stop": category, "expect": {"safety_events": {"eq": 1}},
                                 **(LINK if link else {})})
    return {**r.summary["metrics"], "trace": r.trace, "interventions": r.summary["safety"]["interventions"]}


def test_stopping_time_and_distance_per_category_on_hit_at_its_top_planned_speed():
    c0, c1, c2 = (_stop(c) for c in (0, 1, 2))
    v0 = c1["stop_peak_speed_deg_s"]  # the fastest joint at the press: the plan's peak (wrist_1, 45.8°/s)
    assert v0 > 40
    for m in (c1, c2):  # the ramp: v0 / a, v0² / 2a on the fastest joint
        assert m["stop_time_s"] == pytest.approx(v0 / 360, abs=0.005)
        assert m["stop_distance_deg"] == pytest.approx(v0**2 / 720, rel=0.05)
        tr = m["trace"]
        k0 = int(round(1.0 / 1e-3))
        decel = np.abs(np.diff(np.degrees(tr.qd[k0 : k0 + 120]), axis=0)) / 1e-3
        assert np.percentile(decel, 99) < 1.5 * 360  # bounded (the gains track the ramp within half its bound)
    # category 0 drops the torque at once and the brakes stop it: sooner and shorter than the controlled stop
    assert c0["stop_time_s"] < 0.05 and c0["stop_distance_deg"] < 1.0
    assert [e["t"] for e in c0["interventions"] if e["rule"] == "brakes"] == [1.0]
    assert [e["t"] for e in c1["interventions"] if e["rule"] == "brakes"] == [pytest.approx(1.0 + v0 / 360, abs=0.005)]
    assert not [e for e in c2["interventions"] if e["rule"] == "brakes"]  # held, torque on


CANOPEN = {"backend": {"type": "canopen", "clock": "lockstep"}, "rates": {"control_hz": 500}}


def _ramp_in(result) -> float | None:
    return next((e["data"]["duration_s"] for e in result.summary["safety"]["interventions"]
                 if e["rule"] == "ramp-in"), None)


@pytest.mark.parametrize("where", ["simulation", "link", "canopen"])
def test_an_estop_stays_latched_across_runs_until_a_person_clears_it(where, capsys):
    extra = {"simulation": {}, "link": LINK, "canopen": CANOPEN}[where]
    name = "hit-1" if where == "link" else "sim-hit"  # (simulated drives: a rehearsal's latch)
    first = run_scenario(ESTOP, extra)
    assert first.passed and EStopLatch.named(name).latched() is not None
    assert first.summary["safety"]["estop_latched"] == name  # (and the run says so, with what clears it)
    assert f"rehabkit estop clear {name} --by NAME" in run_report(first.summary, Path("out")).split("LATCHED")[1]
    with pytest.raises(SetupError) as refused:
        run_scenario(ESTOP, extra)  # a new session: refused before anything moves
    assert isinstance(refused.value.__cause__, EStopLatchedError) and refused.value.__cause__.latch == name
    sets = [a for k, v in extra.items() for a in ("--set", f"{k}={json.dumps(v)}")]
    assert main(["validate", str(ESTOP), *sets]) == 0  # (the file is valid) and validate says what a run would meet
    assert f"LATCHED the robot's e-stop ({name}) is latched" in capsys.readouterr().out
    assert main(["estop", "list"]) == 0 and f"{name}: LATCHED" in capsys.readouterr().out
    assert main(["estop", "clear", name + "x", "--by", "J. Doe"]) == 2  # a misspelt name clears nothing
    assert suggested(capsys.readouterr().err) == [name]
    assert main(["estop", "clear", name, "--by", "J. Doe"]) == 0  # (the README's command)
    assert capsys.readouterr().out.startswith(f"{name}: cleared by J. Doe (latched since ")
    record = EStopLatch.named(name).record()
    assert not record["latched"] and record["cleared_by"] == "J. Doe" and record["was"]["reason"]
    assert main(["estop", "clear", name, "--by", "M. Roe"]) == 0  # again: nothing latched, nothing cleared
    assert capsys.readouterr().out == f"{name}: not latched\n" and EStopLatch.named(name).record() == record
    # the first session after the clear ramps in (at least 1 s); run to just past the press at 1.0 s, not on through
    # the stop's 0.5 s of hold: the ramp and the latch's return are what it is run for (as safety-report does)
    cleared = run_scenario(ESTOP, {**extra, "duration": 1.05})
    assert _ramp_in(cleared) == pytest.approx(1.0)
    assert EStopLatch.named(name).latched() is not None  # (its own e-stop latched it again)


class _ServedError(Exception):
    """Ends a real-time bridge's serve loop once the test has had its answer."""


@contextmanager
def _serving(bridge, duration: float):
    """``serve(bridge, duration)`` in a thread while the block runs, stopped at the block's end (the loop ticks in
    real time: waiting out ``duration`` after the answer came spent the rest of it stepping the plant for nothing).
    ``duration`` still bounds it should the block hang; the loop's ``finally`` closes the link as before."""
    from rehabkit.hardware.bridge_clocks import serve

    done, reloaded = threading.Event(), bridge.reloaded

    def each_turn() -> None:  # (the loop calls it every tick)
        if done.is_set():
            raise _ServedError
        reloaded()

    def run() -> None:
        with suppress(_ServedError):
            serve(bridge, duration)

    bridge.reloaded = each_turn
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def test_a_running_bridge_clears_its_latch_on_command(hit, tmp_path):
    from rehabkit.cli.estop import clear_over_link
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.link.protocol import CLEARED, ESTOPPED, HOLDING
    from rehabkit.hardware.plant import MujocoPlant

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    bridge = Bridge(MujocoPlant(hit), latch=latch)
    bridge.press_estop(0.0)
    assert latch.latched()["by"] == "robot" and latch.latched()["source"] == "button" and bridge.status & ESTOPPED
    restarted = Bridge(MujocoPlant(hit), latch=latch)  # a restart keeps it latched
    assert restarted.status & ESTOPPED and restarted.status & HOLDING
    with _serving(restarted, 1.0):
        status = clear_over_link("127.0.0.1", restarted.port, 1, "Dr. Ana Ruiz")
        assert not status & ESTOPPED and status & HOLDING  # still held: only a reset starts a session
        assert status & CLEARED  # (a latched e-stop was cleared: `estop clear --bridge` says "cleared")
    record = json.loads(latch.path.read_text())  # who cleared it, from where, in which session's key (none here)
    assert record["cleared_by"] == "Dr. Ana Ruiz" and record["via"] == "the link from 127.0.0.1"
    assert record["key_id"].startswith("none")


def test_clearing_a_running_bridge_where_nothing_is_latched_says_not_latched(hit, tmp_path, capsys):
    """`rehabkit estop clear NAME --bridge` on a bridge whose e-stop is not latched: "not latched" (it said "cleared"),
    exit 0, and the latch file keeps no clear (the bridge's state says whether it cleared a latched one: CLEARED)."""
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.plant import MujocoPlant

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    bridge = Bridge(MujocoPlant(hit), latch=latch)
    with _serving(bridge, 0.5):
        code = main(["estop", "clear", "hit-1", "--by", "J. Doe", "--bridge", f"127.0.0.1:{bridge.port}"])
    assert code == 0 and capsys.readouterr().out == f"hit-1: not latched at the bridge udp://127.0.0.1:{bridge.port}\n"
    assert latch.record().get("cleared_by") is None and [c["latched"] for c in bridge.clears][:1] == [False]


def test_the_keypad_at_the_robot_presses_and_clears_the_estop(tmp_path):
    """The keypad's e and c, each said once (a c where nothing is latched said both "clear (not latched)" and
    "cleared"); the console says the keypad is on and who may clear; stopped by SIGTERM, the bridge says what it
    wrote (it said "nothing was written" beside its --stats)."""
    import signal
    import subprocess
    import sys

    latch, stats = tmp_path / "hit-1.json", tmp_path / "stats.json"
    proc = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--keypad", "--duration", "20",
                             "--latch-file", str(latch), "--stats", str(stats), "--security-log",
                             str(tmp_path / "security.jsonl")], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().startswith("bridge:")

        def said_after(key: str) -> str:
            proc.stdin.write(key + "\n")
            proc.stdin.flush()
            return proc.stdout.readline()  # (said once done)

        assert said_after("e") == "keypad: e-stop pressed, latched\n"
        assert json.loads(latch.read_text())["source"] == "keypad"  # (pressed at the robot: its keypad's e)
        assert said_after("c") == "keypad: e-stop cleared; the next session ramps in\n"
        assert json.loads(latch.read_text())["cleared_by"] == "the keypad at the robot"
        assert said_after("c") == "keypad: e-stop not latched (nothing to clear)\n"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    finally:
        proc.kill()
        proc.wait()
    lines = err.splitlines()
    assert proc.returncode == 143 and lines[-1] == (f"bridge: stopped by SIGTERM; wrote --stats {stats}, the security "
                                                    f"log {tmp_path / 'security.jsonl'} (0 lines)")
    assert "bridge: a latched e-stop is cleared in any session" in lines and "bridge: keypad on standard input: e " \
        "presses the e-stop, c clears it, a lets a new host take the session over" in lines
    assert [c["latched"] for c in json.loads(stats.read_text())["estop_clears"]] == [True, False]


def _lockstep_reset(port: int, key, q0: np.ndarray) -> tuple[object, int]:
    """A host's session on a lock-step bridge: its reset at link time 0 (as every run's first tick); the host's link
    and the status of the bridge's answer."""
    from rehabkit.hardware.link.host_end import HostLink
    from rehabkit.hardware.link.protocol import CMD_RESET, COMMAND, HEADER, STATE, TICK, Receiver

    wire = HostLink("127.0.0.1", port, 1, key, Receiver(STATE, 1, 6), 0.001)
    wire.open_session()
    statuses = []
    wire.send(COMMAND, q0, 0.0, CMD_RESET | TICK)
    assert wire.tick_lockstep(lambda: statuses.extend(HEADER.unpack_from(p)[9] for p, _ in wire.arrived(
        lambda: 0.0, True)), sent=True)
    return wire, statuses[-1]


def test_a_lockstep_bridge_cleared_of_its_estop_serves_the_next_host_and_reads_its_keypad_unticked(hit, tmp_path):
    """The README's lab commands on a lock-step bridge (a new user's report): the keypad's e latches the e-stop with
    no host ticking the bridge; a host is refused (the states declare that only the clearing key clears: the hint
    says so); the clear under the clearing key answers "cleared", a second "not latched"; the next host's reset at
    link time 0 — the same time as the refused host's — starts a session that ramps in (it was answered again with
    the refused host's latched state: every later host refused until the bridge restarted)."""
    from rehabkit.cli.estop import clear_over_link
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.bridge_clocks import serve_lockstep
    from rehabkit.hardware.bridge_says import clear_right
    from rehabkit.hardware.keypad import Keypad
    from rehabkit.hardware.link.protocol import CLEAR_BY_KEY, CLEARED, CLOCK, ENABLED, ESTOPPED, RAMP_IN
    from rehabkit.hardware.plant import MujocoPlant
    from rehabkit.hardware.security.keys import new_key

    key, clearing = new_key("hit-1", tmp_path / "hit-1.key"), new_key("hit-1", tmp_path / "clear.key")
    latch = EStopLatch.for_robot("hit", 1, tmp_path / "hit-1.json")
    keys_in, keys_out = os.pipe()
    bridge = Bridge(MujocoPlant(hit), key=key, clear_key=clearing, latch=latch, keypad=Keypad(keys_in))
    thread = threading.Thread(target=serve_lockstep, args=(bridge, 1.0), daemon=True)
    thread.start()
    q0 = np.radians([0.0, 90.0, 90.0, 30.0, -90.0, 90.0])
    try:
        os.write(keys_out, b"e\n")  # at the robot, no host running
        until = time.monotonic() + 5.0
        while latch.latched() is None:  # (polled: the bridge reads its keypad between datagrams)
            assert time.monotonic() < until, "the keypad's e was not read"
            time.sleep(0.01)
        assert latch.latched()["by"] == "robot" and latch.latched()["source"] == "keypad"
        refused, status = _lockstep_reset(bridge.port, key, q0)
        refused.close()
        assert status & ESTOPPED and status & CLEAR_BY_KEY and clear_right(status) == "key"
        assert clear_over_link("127.0.0.1", bridge.port, 1, "Dr. Ana Ruiz", key_file=str(clearing.path)) & CLEARED
        assert not clear_over_link("127.0.0.1", bridge.port, 1, "Dr. Ana Ruiz", key_file=str(clearing.path)) & CLEARED
        wire, status = _lockstep_reset(bridge.port, key, q0)
        assert status & ENABLED and status & RAMP_IN and not status & ESTOPPED
        assert [(c["by"], c["latched"]) for c in bridge.clears] == [("Dr. Ana Ruiz", True), ("Dr. Ana Ruiz", False)]
        wire.send(CLOCK, np.zeros(0), 1.0)  # (the link's time at the bridge's duration: it stops)
        thread.join(5.0)
        wire.close()
    finally:
        os.close(keys_out)
    assert not thread.is_alive() and bridge.repeated_ticks == 0
