"""A user's own robots (examples/robots: a DH table, a URDF and an MJCF file) reach Cartesian targets past the
world's obstacles with each generic planner, and meet their scenario's expectations; the OMPL planner's path is
free of the world when checked by MuJoCo along the timed reference."""

from pathlib import Path

import numpy as np
import pytest

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.cspace.scene_check import SceneCollision

EXAMPLES = Path(__file__).parents[1] / "examples" / "robots"
ROBOTS = ["dh_arm3", "urdf_arm4", "mjcf_arm5"]


_RUNS: dict[tuple[str, str], tuple[Runner, object]] = {}


def _run(robot: str, planner: str):
    """Each example with each planner, run once for the tests of this module."""
    if (robot, planner) not in _RUNS:
        runner = Runner(load_scenario(EXAMPLES / f"{robot}.yaml", {"planner.type": planner}))
        _RUNS[robot, planner] = runner, runner.run()
    return _RUNS[robot, planner]


@pytest.mark.parametrize("planner", ["ompl-joint", "cartesian"])
@pytest.mark.parametrize("robot", ROBOTS)
def test_an_own_robot_meets_its_expectations_with_each_generic_planner(robot, planner):
    _, result = _run(robot, planner)
    assert result.passed, result.failures
    m = result.metrics
    assert m["reaches_completed"] == m["reaches"] >= 2
    assert m["final_position_error_m"] < 0.002 and m["contact_steps"] == 0
    if planner == "ompl-joint":
        assert m["states_checked"] > 0
    else:
        assert m["ik_samples"] > 20 and m["path_length_ratio"] == pytest.approx(1.0, abs=0.02)  # straight lines


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_joint_space_path_goes_around_the_obstacles_not_through_them(robot):
    runner, result = _run(robot, "ompl-joint")
    checker = SceneCollision(runner.setup.robot.model, runner.sc.world)  # the true geometry, no clearance
    q_ref = np.asarray(result.trace.q_ref)  # the timed reference, every control step
    assert len(q_ref) > 5000 and checker.first_collision(q_ref) == -1
    left, right = np.radians(result.summary["plans"][0]["waypoints_deg"][-2:])
    straight = left + np.linspace(0, 1, 200)[:, None] * (right - left)
    if robot == "urdf_arm4":  # no via points: the pillar stands between its targets (the others route by them)
        assert result.metrics["path_vertices"] > 4 and result.metrics["path_length_ratio"] > 1.3  # a detour...
        assert checker.first_collision(straight) >= 0  # ...which the straight joint-space line would hit


def test_a_joint_plan_to_where_the_arm_already_is_holds_it():
    """The start held (a plan from the start posture to itself, as a session's first plan is): a path of one
    point is a hold, not an index error — validate and the run's first plan both check it."""
    from rehabkit.cspace.timing import RestToRestPath

    q = np.array([0.1, -0.2, 0.3])
    path = RestToRestPath(q[None, :], np.zeros(0))
    qs, qds, qdds = path.sample(np.array([0.0, 0.5]))
    assert path.duration == 0.0 and np.array_equal(qs, [q, q]) and not qds.any() and not qdds.any()
    loaded = load_scenario(EXAMPLES.parent / "ros_session" / "arm4_session.yaml",
                           {"planner.type": "ompl-joint", "duration": 1.0})
    result = Runner(loaded).run()
    assert result.summary["plans"][0]["duration_s"] >= 0.0 and result.metrics["safety_events"] == 0
    held, moving = (np.degrees(np.abs(result.trace.q[k] - np.radians([0, 20, 60, 20]))).max() for k in (490, 990))
    assert held < 0.01 and moving > 1.0  # held until the replan to 'left' at 0.5 s


def test_a_plan_from_a_joint_resting_a_hair_past_its_range_may_stay_there_not_go_further():
    """A joint resting at its limit (a target exactly there, a simulated limit giving a little) starts its plan a
    hair past the range: the plan is refused only if it goes further out — not for where the robot already is."""
    from rehabkit.core.kinds.interfaces import Plan
    from rehabkit.core.safety.limit_breach import plan_breach
    from rehabkit.cspace.timing import RestToRestPath

    runner = Runner(load_scenario(EXAMPLES / "urdf_arm4.yaml"))
    model = runner.build().robot.model
    upper = model.limits.upper[1]
    start = np.array([0.0, upper + 6.5e-8, 0.5, 0.0])  # (the excess a new user met: 3.7e-6 deg)

    def plan(to: np.ndarray) -> Plan:
        return Plan(RestToRestPath(np.array([start, to]), np.array([1.0])))

    assert plan_breach(plan(start + [0.3, 0.0, 0.0, 0.0]), model) is None  # stays there
    assert plan_breach(plan(start - [0.0, 0.2, 0.0, 0.0]), model) is None  # comes back in
    further = plan_breach(plan(start + [0.0, 0.01, 0.0, 0.0]), model)  # goes further out: refused
    assert further.joint == model.joint_names[1] and further.quantity == "position" and further.value > start[1]
