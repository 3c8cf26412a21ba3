"""The numeric IK every robot gets from its Pinocchio model: position-only, full-pose and pointing targets reached
within the joint limits, the solution nearest the posture first, and an unreachable target refused where it is
written."""

import numpy as np
import pytest
import yaml

from plugins.robots.dh import DHRobot
from rehabkit.core.kinds.errors import PlanningError
from rehabkit.core.setup.targets import axis_error_deg
from rehabkit.models.dh import DHRobotSpec
from tests.conftest import ROOT
from tests.located import located, refusal
from tests.test_cli import cli
from tests.test_user_robot_errors import ARM3


@pytest.fixture(scope="module")
def arm3():
    spec = yaml.safe_load(ARM3)["robot"]
    spec.pop("type")
    return DHRobot(DHRobotSpec.model_validate(spec))


def _within(robot, q):
    lim = robot.model.limits
    return bool(np.all(q >= lim.lower - 1e-9) and np.all(q <= lim.upper + 1e-9))


def test_a_3dof_dh_arm_reaches_positions_within_its_limits(arm3):
    rng = np.random.default_rng(0)
    lim = arm3.model.limits
    errors = []
    for q in rng.uniform(lim.lower, lim.upper, (30, 3)):
        want = arm3.fk(q)
        (best, *_) = arm3.solve_ik(want, free="xyz")
        assert _within(arm3, best)
        errors.append(np.linalg.norm(arm3.fk(best)[:3, 3] - want[:3, 3]))
    assert max(errors) < 2e-5


def test_a_scaras_tool_pointing_down_reaches_position_only_targets():
    """A SCARA's tool points down, half a turn from a point target's axes: pink's 6-D error broke there (a
    reachable point was 'out of reach, 74 mm away'); the position alone is now what the descent follows."""
    spec = yaml.safe_load((ROOT / "examples" / "robots" / "dh_scara.yaml").read_text())["robot"]
    spec.pop("type")
    scara = DHRobot(DHRobotSpec.model_validate(spec))
    rng = np.random.default_rng(1)
    lim = scara.model.limits
    errors = []
    for q in rng.uniform(lim.lower, lim.upper, (10, scara.model.dof)):
        want = np.eye(4)
        want[:3, 3] = scara.fk(q)[:3, 3]  # (a point: identity axes, as a position target's are)
        (best, *_) = scara.solve_ik(want, free="xyz")
        assert _within(scara, best)
        errors.append(np.linalg.norm(scara.fk(best)[:3, 3] - want[:3, 3]))
    assert max(errors) < 2e-5


def test_the_solution_nearest_the_posture_comes_first(arm3):
    q = np.radians([30.0, 40.0, 70.0])
    sols = arm3.solve_ik(arm3.fk(q), reference=q + 0.05, free="xyz")
    assert len(sols) >= 2  # elbow up and down (and the turned-round shoulder)
    assert np.abs(sols[0] - q).max() < 1e-4
    assert all(np.linalg.norm(s - q - 0.05) >= np.linalg.norm(sols[0] - q - 0.05) for s in sols)


def test_a_6dof_arm_reaches_whole_poses_as_its_analytic_ik_does(hit):
    rng = np.random.default_rng(1)
    lim = hit.model.limits
    solved = 0
    for q in rng.uniform(lim.lower, lim.upper, (20, 6)):
        want = hit.fk(q)
        sols = hit.numeric_ik.solve(want)
        assert hit.ik(want)  # the analytic IK reaches it too
        if sols:
            solved += 1
            got = hit.fk(sols[0])
            assert np.linalg.norm(got[:3, 3] - want[:3, 3]) < 2e-5
            assert axis_error_deg(got[:3, :3], want[:3, :3]) < 0.01
            assert _within(hit, sols[0])
    assert solved >= 19


def test_a_pointing_target_leaves_the_turn_about_the_tool_axis_free(hit):
    q = np.radians([10.0, -20.0, 30.0, 15.0, 40.0, -25.0])
    want = hit.fk(q)
    turned = want.copy()  # the same tool z axis, turned 60 degrees about it: no 6-DoF IK answer needed
    c, s = np.cos(np.radians(60)), np.sin(np.radians(60))
    turned[:3, :3] = want[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    (best, *_) = hit.solve_ik(turned, reference=q, free="z")
    got = hit.fk(best)
    assert np.linalg.norm(got[:3, 3] - want[:3, 3]) < 2e-5
    assert np.degrees(np.arccos(np.clip(got[:3, 2] @ want[:3, 2], -1, 1))) < 0.01  # z points where asked
    assert axis_error_deg(got[:3, :3], turned[:3, :3], "z") < 0.01


def test_an_unreachable_target_says_how_near_the_arm_came(arm3):
    far = np.eye(4)
    far[:3, 3] = [2.0, 0.0, 0.2]
    assert arm3.solve_ik(far, free="xyz") == []
    assert arm3.numeric_ik.closest_m == pytest.approx(2.0 - 0.55, abs=2e-3)  # shoulder at z = 0.2, reach 0.55


def test_validate_locates_an_unreachable_cartesian_target(tmp_path):
    text = ARM3.replace("{name: B, joints_deg: [40, 60, 20]}", "{name: B, position: [1.5, 0.0, 0.3]}")
    path = tmp_path / "far.yaml"
    path.write_text(text)
    done = cli("validate", str(path))
    assert done.returncode == 2, done.stderr
    line = text.splitlines().index("    - {name: B, position: [1.5, 0.0, 0.3]}") + 1
    assert [(n, at) for _, n, _, at in located(done.stderr)] == [(line, "task.targets.1.position")], done.stderr
    cause = refusal(path).__cause__  # what validate says there: the planner's refusal of B (its words: unreachable())
    assert (type(cause), cause.target) == (PlanningError, "B")
