"""Workspace planners end to end: timing, junction, failure handling, CLIK."""

import types

import numpy as np
import pytest

from rehabkit.core.kinds.interfaces import Context, PlanningError, PlanRequest, Target
from rehabkit.workspace.grid import INNER, UNREACHABLE, VoxelWorkspace
from rehabkit.workspace.trajectory import Junction, TimedPath, resample, smooth_path, trapezoid


def test_trapezoid_respects_limits_and_rests_at_both_ends():
    path = smooth_path(np.array([[0, 0, 0], [0.2, 0.02, 0], [0.3, 0.1, 0.05], [0.3, 0.2, 0.1]], float))
    tp = TimedPath(path, v_max=0.1, a_max=0.2)
    t = np.linspace(0, tp.duration, 4001)
    x, xd, xdd = tp.sample(t)
    speed = np.linalg.norm(xd, axis=1)
    assert speed.max() <= 0.1 + 1e-9 and speed[0] == 0 and speed[-1] < 1e-9
    np.testing.assert_allclose(x[[0, -1]], path[[0, -1]], atol=1e-12)
    # numerical derivative of position matches the reported velocity
    np.testing.assert_allclose(np.gradient(x, t, axis=0)[5:-5], xd[5:-5], atol=2e-3)
    ta, tc, vp = trapezoid(tp.length, 0.1, 0.2)
    assert tp.duration == pytest.approx(2 * ta + tc) and vp == 0.1


def test_short_path_gets_a_triangular_profile():
    ta, tc, vp = trapezoid(0.01, v_max=0.5, a_max=1.0)
    assert tc == 0 and vp < 0.5 and ta == pytest.approx(0.1)


def test_junction_is_continuous_in_position_and_velocity():
    old = TimedPath(resample(np.array([[0, 0, 0], [0.4, 0, 0]], float), 0.001), 0.1, 0.2)
    new = TimedPath(resample(np.array([[0.1, 0, 0], [0.1, 0.3, 0]], float), 0.001), 0.1, 0.2)
    off, blend = 1.0, 0.5
    j = Junction(old, off, new, blend)
    x0, v0, _ = j.sample([0.0])
    xo, vo, _ = old.sample([off])
    np.testing.assert_allclose(x0, xo, atol=1e-12)
    np.testing.assert_allclose(v0, vo, atol=1e-12)
    xb, vb, _ = j.sample([blend + 1e-9])
    xn, vn, _ = new.sample([blend + 1e-9])
    np.testing.assert_allclose(xb, xn, atol=1e-9)
    np.testing.assert_allclose(vb, vn, atol=1e-6)
    t = np.linspace(0, 2 * blend, 2001)
    x, v, _ = j.sample(t)
    assert np.abs(np.diff(v, axis=0)).max() < 1e-3  # no velocity jump anywhere in the blend


def _cup_robot():
    lab = np.zeros((44, 44, 5), np.uint8)
    lab[2:42, 2:42, 1:4] = INNER
    lab[22, 8:36, 1:4] = UNREACHABLE
    lab[6:23, 8, 1:4] = UNREACHABLE
    lab[6:23, 35, 1:4] = UNREACHABLE
    ws = VoxelWorkspace(np.zeros(3), 0.01, lab)
    model = types.SimpleNamespace(name="cup")
    return types.SimpleNamespace(model=model, workspace=lambda resolution=0.01: ws,
                                 fk=lambda q: np.block([[np.eye(3), np.asarray(q)[:3, None]], [np.zeros(3), 1]]))


def _request(robot, start, goal):
    pose = np.eye(4)
    pose[:3, 3] = goal
    return PlanRequest(0.0, np.asarray(start, float), np.zeros(3), [Target("g", pose=pose)], robot)


def test_greedy_planner_failure_is_reported_or_falls_back():
    from rehabkit_plugins.planners.voxel_hill import VoxelHill

    from rehabkit.workspace.planning import VoxelPlannerConfig

    robot = _cup_robot()
    ctx = Context(scenario_dir=None, rng=np.random.default_rng(0), control_dt=0.001, robot=robot)
    start, goal = [0.18, 0.21, 0.02], [0.32, 0.21, 0.02]
    with pytest.raises(PlanningError) as refused:
        VoxelHill(VoxelPlannerConfig(), ctx).plan(_request(robot, start, goal))
    assert refused.value.code in ("no-arrival", "stuck")  # (the greedy search's own failure, as its code)
    plan = VoxelHill(VoxelPlannerConfig(fallback="astar"), ctx).plan(_request(robot, start, goal))
    assert plan.diagnostics["fallbacks"] == 1
    x = plan.trajectory.sample(np.linspace(0, plan.trajectory.duration, 500))[0]
    assert np.all(robot.workspace().label(x) >= 1) and np.linalg.norm(x[-1] - goal) < 0.011


@pytest.fixture(scope="module")
def lexos():
    from rehabkit_plugins.robots.lexos import LexosConfig, LexosRobot

    return LexosRobot(LexosConfig())


def test_clik_converges_to_the_target_and_uses_the_null_space(lexos):
    from rehabkit_plugins.controllers.clik_pd import ClikPD, ClikPDConfig

    ctx = Context(scenario_dir=None, rng=np.random.default_rng(0), control_dt=0.001, robot=lexos)
    q0 = np.radians([20, -45, 0, -70])
    target = lexos.fk(np.radians([40, -60, 30, -50]))[:3, 3]
    results = {}
    for k0 in (0.0, 5.0):
        c = ClikPD(ClikPDConfig(k0=k0), ctx)
        for _ in range(3000):  # 3 s of closed-loop IK toward a fixed point
            c.compute(0.0, q0, np.zeros(4), target, np.zeros(3), np.zeros(3))
        q_r = c.joint_reference
        assert np.linalg.norm(lexos.fk(q_r)[:3, 3] - target) < 1e-4
        lim = lexos.model.limits
        assert np.all(q_r >= lim.lower) and np.all(q_r <= lim.upper)
        results[k0] = np.sum(((q_r - (lim.lower + lim.upper) / 2) / (lim.upper - lim.lower)) ** 2)
    assert results[5.0] < results[0.0]  # redundancy spent moving toward mid-range


LEXOS_STATIC = """\
name: lexos-static
robot: {type: lexos}
planner: {type: voxel-beam, fallback: astar, v_max: 0.06, a_max: 0.15}
controller: {type: clik-pd}
task:
  targets:
    - {name: start, joints_deg: [20, -45, 0, -70]}
    - {name: target1, position: [0.82, 0.33, -0.43]}
    - {name: target2, position: [0.52, -0.50, -0.26]}
    - {name: target3, position: [0.56, 0.52, -0.27]}
  sequence: [start]
  events:
    - {at: 4.0, action: replan, sequence: [target1]}
    - {at: 9.5, action: replan, sequence: [target2]}
    - {at: 14.0, action: replan, sequence: [target3]}
duration: 20.5
expect:
  goal_reach_error_max_mm: {lt: 5}
  path_outside_workspace_samples: {eq: 0}
  joint_limit_excess_deg: {lt: 0.5}
"""


def test_reaching_out_of_reach_targets_through_the_concave_workspace(tmp_path, run_scenario):
    p = tmp_path / "lexos_static.yaml"
    p.write_text(LEXOS_STATIC)
    r = run_scenario(p)
    assert r.passed, r.failures
    plans = r.summary["plans"]
    assert [p["t"] for p in plans] == [0.0, 4.0, 9.5, 14.0]
    assert all(p.get("proxy_targets") == 1 for p in plans[1:])  # all three targets are out of reach
    assert plans[2].get("searched_legs") == 1  # proxy 1 → proxy 2 cannot be a straight line
    assert plans[3]["junction_s"] > 0  # target 3 arrives while the arm still travels to proxy 2
    assert r.metrics["goals_reached"] == 3 and r.metrics["proxy_bisection_lookups"] <= 7
    x_ref = r.trace.x_ref
    k = int(14.0 / 0.001)
    assert np.linalg.norm(x_ref[k] - x_ref[k - 1]) < 1e-3  # no jump in the reference at the junction
    assert r.metrics["cartesian_tracking_max_mm"] < 5
