"""The safety envelope: per-joint limits, keep-in box, interaction force, ramps, clipping episodes, heartbeat."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from rehabkit.api import run_scenario
from rehabkit.core.safety.layer import SafetyLayer
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.scenario.safety import SafetyConfig
from tests.conftest import SCENARIOS, checked
from tests.located import where

HIT = SCENARIOS / "hit_roundtrip.yaml"
# the hand leaves this box (robot base frame) on the way from A to B, at z = -0.15 m, about 0.85 s in
BOX = {"keep_in": {"min": [-0.8, -0.4, -0.15], "max": [0.0, 0.4, 0.2], "frame": "base"}}


def _mid(hit):
    lim = hit.model.limits
    return (lim.lower + lim.upper) / 2


def test_keep_in_box_trips_when_the_hand_leaves_it(hit):
    cfg = SafetyConfig.model_validate({"keep_in": {"min": [-1, -1, -1], "max": [1, 1, 0.5]}})
    hand = np.array([0.2, 0.0, 0.0])
    layer = SafetyLayer(hit.model, cfg, gravity=hit.gravity_torque, hand=lambda q: hand)
    tau = np.ones(6)
    assert np.array_equal(checked(layer, 0.0, _mid(hit), np.zeros(6), tau.copy()), tau)
    hand[2] = 0.52
    checked(layer, 0.5, _mid(hit), np.zeros(6), tau.copy())
    ev = layer.events[0]
    assert ev.rule == "keep-in" and ev.data["axis"] == "z" and ev.value == pytest.approx(0.52) and ev.limit == 0.5
    assert ev.data["side"] == "max" and layer.tripped


def test_interaction_force_above_the_limit_trips(hit):
    layer = SafetyLayer(hit.model, SafetyConfig(interaction_force_n=30.0), gravity=hit.gravity_torque)
    layer.check_force(0.1, _mid(hit), np.array([10.0, 20.0, 0.0]))
    assert not layer.tripped
    layer.check_force(0.2, _mid(hit), np.array([30.0, 20.0, 0.0]))
    ev = layer.events[0]
    assert ev.rule == "interaction-force" and ev.value == pytest.approx(np.hypot(30, 20)) and ev.limit == 30.0


def test_clipping_steps_in_a_row_are_one_intervention(hit):
    layer = SafetyLayer(hit.model, SafetyConfig(), dt=1e-3)
    tau = np.zeros(6)
    for k in range(10):
        tau[1] = hit.model.limits.effort[1] * (1.5 + 0.1 * k)
        out = checked(layer, k * 1e-3, _mid(hit), np.zeros(6), tau.copy())
        assert abs(out[1]) == pytest.approx(hit.model.limits.effort[1])
    checked(layer, 0.05, _mid(hit), np.zeros(6), tau.copy())  # a new episode later
    clips = [e for e in layer.interventions if e.rule == "torque-clip"]
    assert len(clips) == 2 and clips[0].data["steps"] == 10 and clips[0].joint == "shoulder_2"
    assert clips[0].value == pytest.approx(hit.model.limits.effort[1] * 2.4)  # the episode's peak
    assert not layer.tripped and layer.saturated_steps == 11


def test_envelope_values_are_checked_where_written(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump({"extends": str(HIT), "safety": {
        "keep_in": {"min": [0, 0, 0], "max": [1, -1, 1]}, "joints": {"elbow_1": {"range_deg": [100, 20]}},
        "ramp_in_s": -1}}))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert where(err.value) == [(4, 5, "safety.joints.elbow_1"), (8, 3, "safety.keep_in"), (17, 14, "safety.ramp_in_s")]


@pytest.fixture(scope="module")
def box_run():
    return run_scenario(HIT, {"safety": {**BOX, "stop_after_s": 0.3}, "expect": {"safety_events": {"eq": 1}}})


def test_hand_leaving_the_box_stops_the_run_in_simulation(box_run, hit):
    ev = box_run.summary["safety"]["events"]
    assert len(ev) == 1 and ev[0]["rule"] == "keep-in" and ev[0]["data"]["axis"] == "z"
    assert 0.6 < ev[0]["t"] < 1.1 and ev[0]["limit"] == pytest.approx(-0.15 + hit.model.base_pose[2, 3])
    hand = hit.ee_world(box_run.trace.q)
    k = int(round(ev[0]["t"] * 1000))
    assert hand[k, 2] < ev[0]["limit"] <= hand[k - 1, 2] + 1e-9  # the first sample outside, not later
    speed = np.abs(box_run.trace.qd).max(axis=1)
    assert speed[-1] < 0.3 * speed[k]  # held: slowing to a stop afterwards
    assert box_run.summary["metrics"]["sim_time_s"] == pytest.approx(ev[0]["t"] + 0.3, abs=2e-3)
    assert box_run.metrics["safety_interventions"] == 1
    # and it was said before moving: the plan's hand path, against the same box, leaves it where the hand did
    (warning,) = box_run.summary["safety"]["plan_warnings"]
    assert warning["t"] == 0.0 and abs(warning["at_s"] - ev[0]["t"]) < 0.02
    assert (warning["axis"], warning["side"]) == (ev[0]["data"]["axis"], ev[0]["data"]["side"]) == ("z", "min")


def test_validate_says_before_any_run_where_the_plan_leaves_the_box(box_run, tmp_path):
    """The same warning `run` gives before it moves, from `validate` (the scenario is valid: exit 0)."""
    from tests.test_cli import cli

    (tmp_path / "box.yaml").write_text(yaml.safe_dump({"extends": str(HIT), "safety": BOX}))
    out = cli("validate", tmp_path / "box.yaml")
    assert out.returncode == 0
    (said,) = [line.strip() for line in out.stdout.splitlines() if line.strip().startswith("PLAN")]
    assert said == "PLAN    " + box_run.summary["safety"]["plan_warnings"][0]["message"]


def test_ramp_in_starts_from_holding_and_ramp_out_ends_there(scenario_run):
    result = run_scenario(HIT, {"safety": {"ramp_in_s": 0.5, "ramp_out_s": 0.5}})
    iv = result.summary["safety"]["interventions"]
    assert [e["rule"] for e in iv] == ["ramp-in", "ramp-out"] and iv[1]["t"] == pytest.approx(8.0)
    assert result.metrics["safety_interventions"] == 0  # ramps are planned, not breaches
    # the plan starts moving at once: during the ramp the arm lags (a scenario starts moving after its ramp-in)
    assert result.metrics["tracking_max_deg"] < 5.0 and result.metrics["final_position_error_m"] < 0.005
    tau = result.trace.tau
    plain = scenario_run(HIT).trace.tau  # the round trip as written (its scenario test's run)
    assert np.abs(tau[400] - plain[400]).max() > 1e-3  # still blending at 0.4 s
    assert np.abs(tau[600] - plain[600]).max() < 0.5  # at most small after-effects of the ramp after it
    assert np.abs(np.diff(tau[:700], axis=0)).max() < 1.0  # no jump anywhere in the ramp [N·m per ms]


def test_heartbeat_sets_the_links_timing(hit):
    from pathlib import Path

    from rehabkit.core.kinds.interfaces import Context
    from rehabkit.hardware.backend import HardwareBackend, HardwareConfig

    safety = SafetyConfig.model_validate({"heartbeat": {"command_timeout_ms": 80, "state_timeout_ms": 150,
                                                        "hold_after_ms": 4}})
    ctx = Context(Path("."), np.random.default_rng(0), 0.001, robot=hit, robot_spec={"type": "hit"}, safety=safety)
    backend = HardwareBackend(HardwareConfig(spawn_bridge=False, port=9), ctx)
    try:
        assert backend.config.bridge_watchdog_ms == 80 and backend.config.state_timeout_s == pytest.approx(0.15)
        assert backend.config.bridge_stale_ms == 4
    finally:
        backend.close()
    with pytest.raises(ValueError, match="hold_after_ms .50. must be below command_timeout_ms .20."):
        SafetyConfig.model_validate({"heartbeat": {"command_timeout_ms": 20, "hold_after_ms": 50}})
    assert SafetyConfig.model_validate({"heartbeat": {"command_timeout_ms": 6}}).heartbeat.hold_after == 3.0


def test_the_patients_comfort_force_stops_a_session_that_presses_too_hard():
    result = run_scenario(SCENARIOS / "lexos_patient.yaml", {"patient": {"comfort": {"max_interaction_force_n": 20}}})
    ev = result.summary["safety"]["events"]
    assert len(ev) == 1 and ev[0]["rule"] == "interaction-force" and ev[0]["limit"] == 20.0
    assert 20.0 < ev[0]["value"] < 21.0  # caught at the first step above the limit
    assert np.linalg.norm(ev[0]["data"]["force_n"]) == pytest.approx(ev[0]["value"], abs=1e-2)
    assert 4.0 < ev[0]["t"] < 10.0  # during the first reach (the ball shows at 4 s)
    assert result.summary["metrics"]["sim_time_s"] == pytest.approx(ev[0]["t"] + 0.5, abs=2e-3)


def test_a_force_limit_without_a_force_source_is_refused():
    from rehabkit.core.run.runner import SetupError

    with pytest.raises(SetupError) as refused:
        run_scenario(HIT, {"safety": {"interaction_force_n": 50}})
    assert [d.path for d in refused.value.diagnostics] == ["safety.interaction_force_n"]
