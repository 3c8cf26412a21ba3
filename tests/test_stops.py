"""Stop categories (IEC 60204-1) and the latched e-stop (ISO 13850): what each category sends, what a stop takes on
HIT at its top planned speed, in simulation and over the link, and an e-stop that outlives the session."""

from __future__ import annotations

import json
import tempfile
import threading
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
from tests.located import set_located, suggested

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


def test_a_stop_category_for_an_unknown_rule_is_refused_where_written(capsys):
    code = main(["validate", str(ESTOP), "--set", "safety.stop_category.estop=1"])
    err = capsys.readouterr().err
    assert (code, set_located(err)) == (2, [("safety.stop_category.estop", "safety.stop_category.estop")])
    assert suggested(err) == ["e-stop"]  # (the fix)


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
    cleared = run_scenario(ESTOP, extra)  # the first session after the clear ramps in (at least 1 s)
    assert _ramp_in(cleared) == pytest.approx(1.0)
    assert EStopLatch.named(name).latched() is not None  # (its own e-stop latched it again)


def test_a_running_bridge_clears_its_latch_on_command(hit, tmp_path):
    from rehabkit.cli.estop import clear_over_link
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.bridge_clocks import serve
    from rehabkit.hardware.link.protocol import CLEARED, ESTOPPED, HOLDING
    from rehabkit.hardware.plant import MujocoPlant

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    bridge = Bridge(MujocoPlant(hit), latch=latch)
    bridge.press_estop(0.0)
    assert latch.latched()["by"] == "robot" and bridge.status & ESTOPPED
    restarted = Bridge(MujocoPlant(hit), latch=latch)  # a restart keeps it latched
    assert restarted.status & ESTOPPED and restarted.status & HOLDING
    thread = threading.Thread(target=serve, args=(restarted, 1.0), daemon=True)
    thread.start()
    try:
        status = clear_over_link("127.0.0.1", restarted.port, 1, "Dr. Ana Ruiz")
        assert not status & ESTOPPED and status & HOLDING  # still held: only a reset starts a session
        assert status & CLEARED  # (a latched e-stop was cleared: `estop clear --bridge` says "cleared")
    finally:
        thread.join()
    record = json.loads(latch.path.read_text())  # who cleared it, from where, in which session's key (none here)
    assert record["cleared_by"] == "Dr. Ana Ruiz" and record["via"] == "the link from 127.0.0.1"
    assert record["key_id"].startswith("none")


def test_clearing_a_running_bridge_where_nothing_is_latched_says_not_latched(hit, tmp_path, capsys):
    """`rehabkit estop clear NAME --bridge` on a bridge whose e-stop is not latched: "not latched" (it said "cleared"),
    exit 0, and the latch file keeps no clear (the bridge's state says whether it cleared a latched one: CLEARED)."""
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.bridge_clocks import serve
    from rehabkit.hardware.plant import MujocoPlant

    latch = EStopLatch(tmp_path / "hit-1.json", "hit-1")
    bridge = Bridge(MujocoPlant(hit), latch=latch)
    thread = threading.Thread(target=serve, args=(bridge, 0.5), daemon=True)
    thread.start()
    try:
        code = main(["estop", "clear", "hit-1", "--by", "J. Doe", "--bridge", f"127.0.0.1:{bridge.port}"])
    finally:
        thread.join()
    assert code == 0 and capsys.readouterr().out == f"hit-1: not latched at the bridge udp://127.0.0.1:{bridge.port}\n"
    assert latch.record().get("cleared_by") is None and [c["latched"] for c in bridge.clears][:1] == [False]


def test_the_keypad_at_the_robot_presses_and_clears_the_estop(tmp_path):
    import subprocess
    import sys

    latch = tmp_path / "hit-1.json"
    proc = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--keypad", "--duration", "20",
                             "--latch-file", str(latch)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().startswith("bridge:")

        def record_after(key: str) -> dict:
            proc.stdin.write(key + "\n")
            proc.stdin.flush()
            assert proc.stdout.readline().startswith("keypad: e-stop")  # (said once done)
            return json.loads(latch.read_text())

        assert record_after("e")["reason"] == "the e-stop key of the keypad at the robot"
        assert record_after("c")["cleared_by"] == "the keypad at the robot"
    finally:
        proc.kill()
        proc.wait()
