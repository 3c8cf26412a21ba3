import numpy as np
import pytest
from rehabkit_plugins.planners.multi_cubic import (
    MultiCubicConfig,
    MultiCubicPlanner,
    MultiCubicTrajectory,
    solve_multi_cubic,
)
from scipy.interpolate import CubicSpline

from rehabkit.core.kinds.interfaces import PlanningError, PlanRequest, Target


@pytest.mark.parametrize("m", [1, 2, 4, 7])
def test_linear_system_equals_clamped_cubic_spline(m, rng):
    points = rng.uniform(-2, 2, (m + 1, 3))
    durations = rng.uniform(0.5, 3.0, m)
    traj = MultiCubicTrajectory(solve_multi_cubic(points, durations), durations)
    ts = np.linspace(0, traj.duration, 997)
    zero = np.zeros(3)
    ref = CubicSpline(traj.breaks, points, bc_type=((1, zero), (1, zero)))  # independent solver
    q, qd, qdd = traj.sample(ts)
    np.testing.assert_allclose(q, ref(ts), atol=1e-10)
    np.testing.assert_allclose(qd, ref(ts, 1), atol=1e-9)
    np.testing.assert_allclose(qdd, ref(ts, 2), atol=1e-8)


def test_passes_through_via_points_at_rest_ends_and_is_c2(rng):
    points = rng.uniform(-1, 1, (5, 6))
    durations = np.array([2.0, 2.0, 2.0, 2.0])
    traj = MultiCubicTrajectory(solve_multi_cubic(points, durations), durations)
    q, qd, _ = traj.sample(traj.breaks)
    np.testing.assert_allclose(q, points, atol=1e-12)
    np.testing.assert_allclose(qd[[0, -1]], 0.0, atol=1e-12)
    assert traj.continuity().max() < 1e-10
    # and numerically: no jump across a via point
    eps = 1e-7
    for tb in traj.breaks[1:-1]:
        left, right = traj.sample([tb - eps]), traj.sample([tb + eps])
        for a, b in zip(left, right):
            np.testing.assert_allclose(a, b, atol=1e-4)


def test_held_after_the_end():
    points, durations = np.array([[0.0], [1.0]]), np.array([1.0])
    q, qd, qdd = MultiCubicTrajectory(solve_multi_cubic(points, durations), durations).sample([1.0, 5.0])
    np.testing.assert_allclose(q, [[1.0], [1.0]])
    np.testing.assert_allclose(qd, 0.0, atol=1e-12)  # at rest at the end, and held there
    assert qdd[1, 0] == 0.0 and qdd[0, 0] != 0.0  # the last cubic still decelerates at its end point


def test_planner_converts_cartesian_via_points_with_ik(hit):
    qa = np.radians([0, 90, 90, 30, -90, 90])
    a = hit.fk(qa)
    b = a.copy()
    b[:3, 3] = [-0.45, -0.1, -0.3]
    targets = [Target("A", q=qa, pose=a), Target("B", pose=b), Target("C", q=qa, pose=a)]
    plan = MultiCubicPlanner(MultiCubicConfig(segment_durations=[2, 2])).plan(
        PlanRequest(0.0, qa, np.zeros(6), targets, hit))
    q_b = plan.waypoints[1]
    np.testing.assert_allclose(hit.fk(q_b), b, atol=1e-12)
    # the chosen branch is the one nearest A among the solutions within the joint limits
    lim = hit.model.limits
    sols = [qa + ((s - qa + np.pi) % (2 * np.pi) - np.pi) for s in hit.ik(b)]
    inside = [s for s in sols if np.all(s >= lim.lower) and np.all(s <= lim.upper)]
    assert np.linalg.norm(q_b - qa) == pytest.approx(min(np.linalg.norm(s - qa) for s in inside))
    assert plan.diagnostics["ik_roundtrip_position_error_m"] < 1e-12
    assert plan.diagnostics["continuity_max_acceleration_deg_s2"] < 1e-9


def test_wrong_number_of_durations_is_a_planning_error(hit):
    q = np.zeros(6)
    with pytest.raises(PlanningError) as err:
        MultiCubicPlanner(MultiCubicConfig(segment_durations=[1.0])).plan(
            PlanRequest(0.0, q, q, [Target("A", q=q), Target("B", q=q), Target("C", q=q)], hit))
    assert err.value.setting == ("segment_durations",)  # (located there in a scenario)
