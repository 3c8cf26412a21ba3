"""Force-limiting reactions (``safety.reactions``): on the interaction-force limit the robot yields or retreats
instead of stopping stiffly, keeping every other rule; and the compliant test rig (a push through a spring)."""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import yaml

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.scenario.loads import Load
from rehabkit.sim.loads import LoadApplier
from tests.conftest import SCENARIOS

FORCE = SCENARIOS / "safety" / "hit_force.yaml"  # the rig's push rises 30 N/s along world +y; the limit is 30 N
PUSH = np.array([0.0, 1.0, 0.0])


def _run(kind: str, **more):
    over = {"safety.reactions": {"interaction-force": {"type": kind}}, "safety.stop_after_s": 1.0, "expect": None,
            **more}
    runner = Runner(load_scenario(FORCE, over))
    result = runner.run()
    # the robot (the run's constant setup) and the safety layer as the run left it (the session's)
    a = SimpleNamespace(robot=runner.setup.robot, backend=runner.setup.backend, safety=runner.session.safety)
    t, q = result.trace.t, result.trace.q
    k0 = int(np.searchsorted(t, a.safety.tripped_at - 1e-12))
    hands = a.robot.model.to_world(a.robot.fk_batch(q[k0:])[:, :3, 3])
    return result, a, k0, hands


def test_a_yield_gives_way_along_the_push_within_its_speed_bound_and_the_ranges():
    result, a, k0, hands = _run("yield")
    (event,) = a.safety.events
    assert event.rule == "interaction-force" and event.data["reaction"] == "yield"
    m = result.metrics
    assert np.isnan(m["stop_category"]) and m["joints_in_range"] == 1.0
    moved = (hands[-1] - hands[0]) @ PUSH
    assert moved > 0.1  # a set force, never relieved: the arm goes with it (10+ cm in the second after the trip)
    speeds = np.degrees(np.abs(result.trace.qd[k0:]))
    assert speeds.max() < 60.0  # the speed bound (max_speed_deg_s), not reached: no stop
    lim = a.safety.limits
    assert np.all(result.trace.q[k0:] >= lim.lower) and np.all(result.trace.q[k0:] <= lim.upper)


def test_a_retreat_backs_off_at_its_speed_and_holds_once_the_force_is_released():
    # the rig lets go 0.6 s after the trip (at 1.9 s): the retreat stops there and holds its posture
    result, a, k0, hands = _run("retreat", **{"world.loads": [
        {"name": "push", "body": "ft", "force_n": [0, 60, 0], "start_s": 0.3, "ramp_s": 2.0, "release_s": 1.9}]})
    (event,) = a.safety.events
    assert event.data["reaction"] == "retreat" and a.safety.reaction == "retreat"
    t, qd = result.trace.t, np.degrees(np.abs(result.trace.qd))
    going = (t > a.safety.tripped_at + 0.15) & (t < 1.85)
    assert 18.0 < qd[going].max(axis=1).mean() < 22.0  # the fastest joint at retreat_speed_deg_s (20)
    assert (hands[np.searchsorted(t[k0:], 1.85)] - hands[0]) @ PUSH > 0.02  # away along the force
    assert qd[t > 2.2].max() < 0.5  # released: held still
    assert result.metrics["joints_in_range"] == 1.0 and np.isnan(result.metrics["stop_category"])


def test_a_reaction_still_stops_the_robot_at_its_speed_bound():
    result, a, _, _ = _run("yield", **{"safety.reactions": {"interaction-force": {
        "type": "yield", "yield_speed_deg_s": 30, "max_speed_deg_s": 32}}})
    first, stop = a.safety.events
    assert first.data["reaction"] == "yield"
    assert stop.rule == "velocity" and stop.data == {"category": 2, "during": "yield"}
    assert abs(stop.value) > stop.limit == pytest.approx(np.radians(32))
    assert result.metrics["stop_category"] == 2


def test_reactions_are_checked_where_written(tmp_path):
    path = tmp_path / "s.yaml"
    for safety, where, said in (
            ({"interaction_force_n": 30, "reactions": {"interaction-force": {"type": "retreat", "release_n": 35}}},
             "safety", "release_n (35 N) must be below interaction_force_n (30 N)"),
            ({"reactions": {"position": {"type": "yield"}}}, "safety.reactions", "position"),
            ({"reactions": {"interaction-force": {"type": "yield", "yield_speed_deg_s": 80}}},
             "safety.reactions.interaction-force", "yield_speed_deg_s (80) must be below max_speed_deg_s (60)")):
        path.write_text(yaml.safe_dump({"extends": str(FORCE), "safety": safety}))
        with pytest.raises(ScenarioError) as err:
            load_scenario(path)
        text = str(err.value)
        assert where in text and said in text, text


def test_a_spring_rig_pushes_less_as_the_body_gives_way_and_never_pulls():
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body name="b"><joint name="x" type="slide" axis="0 1 0"/>'
        '<geom size="0.05" mass="1"/></body></worldbody></mujoco>')
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rig = LoadApplier(model, [Load(name="p", body="b", force_n=(0, 40, 0), start_s=0.0, ramp_s=1.0,
                                   stiffness_n_m=2000)])
    rig.apply(data, 0.0)  # contact: where the body is now
    for t, given_way, expected in ((0.5, 0.0, 20.0), (0.5, 0.004, 12.0), (1.0, 0.015, 10.0), (1.0, 0.03, 0.0)):
        data.qpos[0] = given_way
        mujoco.mj_forward(model, data)
        rig.apply(data, t)
        assert data.xfrc_applied[1, :3] == pytest.approx([0.0, expected, 0.0], abs=1e-9)


def test_a_yield_over_the_link_is_the_simulations():
    """The host's safety layer reacts the same over the robot link (lock-step): the same trip, the same yield, the
    arm carried as far by the push; the bridge's own backstop (wider ranges and speeds) never steps in."""
    sim, a_sim, _, hands_sim = _run("yield")
    link, a_link, _, hands_link = _run("yield", **{"backend.type": "hardware", "backend.clock": "lockstep"})
    assert [e.rule for e in a_link.safety.events] == ["interaction-force"]
    assert a_link.safety.tripped_at == pytest.approx(a_sim.safety.tripped_at, abs=0.002)
    carried = [(h[-1] - h[0]) @ PUSH for h in (hands_sim, hands_link)]
    assert carried[1] == pytest.approx(carried[0], rel=0.05)
    assert link.metrics["joints_in_range"] == 1.0 and not a_link.backend.holding



def test_a_joint_without_limits_gets_no_wall():
    """A continuous joint (infinite range) yields without a wall and a retreat's reference stays finite."""
    from rehabkit.core.safety.compliance import Compliance
    from rehabkit.core.scenario.safety import ForceReaction

    lo, hi = np.array([-np.inf, -1.0]), np.array([np.inf, 1.0])
    for kind in ("yield", "retreat"):
        c = Compliance(ForceReaction(type=kind), 30.0, 0.0, np.zeros(2), lo, hi, np.array([True, True]),
                       np.array([10.0, 10.0]), np.eye(2) * 0.1, None, None, 100.0, 5.0,
                       lambda q, f: np.array([f[0], f[1]]) * 0.2)
        assert np.all(np.isfinite(c.q_ref)) and c.wall_lo[0] == -np.inf and c.wall_k[0] == 0.0
        c.observe(0.001, np.zeros(2), np.array([40.0, 0.0, 0.0]))
        tau = c.torque(0.001, np.array([50.0, 0.9]), np.zeros(2))  # far out on the free joint, in the other's wall
        assert np.all(np.isfinite(tau)) and (kind == "retreat" or (tau[0] == 0.0 and tau[1] < 0.0))


@pytest.mark.parametrize("reaction", ["yield", "stop"])
def test_a_robot_of_ones_own_with_a_light_wrist_yields_or_stops_without_whipping_it(tmp_path, reaction):
    """The README's URDF arm with a force-torque sensor at its hand and a spring rig pressing down on it. Its wrist
    (1e-3 kg·m²) cannot take the damping that would hold it to the yield's speed at a 1 kHz control rate, so a yield
    holds it (gains within what a control period can apply) while the other joints give way, and the force stays at
    the limit; a stop's hold keeps to the same gains and comes to rest (its wrist had spun at 731 °/s)."""
    scenario = tmp_path / "arm_yield.yaml"
    scenario.write_text(yaml.safe_dump({
        "extends": str(SCENARIOS.parent / "examples" / "robots" / "urdf_arm4.yaml"),
        "controller": {"type": "joint-pd", "gains": "auto", "bandwidth_hz": 10, "feedforward": "inverse-dynamics"},
        "sensors": {"ft": {"type": "force-torque"}},
        "world": {"objects": [], "loads": [{"name": "press", "body": "ft", "force_n": [0, 0, -200], "start_s": 0.5,
                                            "ramp_s": 10.0, "stiffness_n_m": 1000}]},
        "safety": {"interaction_force_n": 10, "hold_kp": 300, "hold_kd": 10, "stop_after_s": 1.0,
                   "reactions": {"interaction-force": {"type": reaction}}},
        "planner": {"type": "multi-cubic", "segment_durations": [1.0]},
        "task": {"targets": [{"name": "home", "joints_deg": [-50, 20, 60, 20]}, {"name": "still", "same_as": "home"}]},
        "duration": 3.0,
        "expect": {"final_position_error_m": None, "tracking_max_deg": None, "safety_events": {"eq": 1},
                   "joints_in_range": {"eq": 1}}}))
    runner = Runner(load_scenario(scenario))
    result = runner.run()
    m = result.metrics
    assert result.passed, result.failures
    if reaction == "yield":
        assert runner.session.safety.reaction == "yield" and m["force_after_trip_peak_n"] <= 11.0  # never escalated
    else:
        assert m["stop_time_s"] < 0.5 and m["stop_peak_speed_deg_s"] < 90.0  # at rest, the wrist not spinning
        assert m["force_after_trip_peak_n"] > 20.0  # (held stiffly against the rig)
