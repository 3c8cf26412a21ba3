"""The cascade of QPs: strict priorities, inequalities on every level, and COMAN's whole-body stack."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from rehabkit_plugins.controllers.qp_stack import QpStack, QpStackConfig
from rehabkit_plugins.robots.coman import ComanConfig, ComanRobot

from rehabkit.core.kinds.interfaces import Context
from rehabkit.core.scenario.models import World
from rehabkit.sim.mujoco import MujocoBackend, MujocoConfig
from rehabkit.wholebody.stack import Inequalities, Level, solve_cascade, solve_weighted
from tests.located import suggested

ARM = ["RShSag", "RShLat", "RShYaw", "RElbj", "RForearmPlate", "RWrj1", "RWrj2"]
BODY = [n for n in ComanRobot(ComanConfig()).model.joint_names if n not in ARM]
CORNERS = [f"{s}_foot_{a}_{b}_link" for s in "lr" for a in ("upper", "lower") for b in ("left", "right")]


def _free(n, G=None, h=None):
    return Inequalities(np.zeros((0, n)) if G is None else G, np.zeros(0) if h is None else h,
                        np.full(n, -1e9), np.full(n, 1e9))


@pytest.mark.parametrize("solver", ["daqp", "proxqp"])
def test_a_lower_level_never_degrades_a_higher_one(solver):
    top = Level(np.array([[1.0, 1.0]]), np.array([1.0]))  # v1 + v2 = 1
    low = Level(np.eye(2), np.array([2.0, 2.0]))  # v = (2, 2), in conflict with the top
    res = solve_cascade([top, low], _free(2), reg=1e-9, solver=solver)
    np.testing.assert_allclose(res.v, [0.5, 0.5], atol=1e-5)
    assert res.residuals[0] < 1e-6
    weighted = solve_weighted([top, low], [1.0, 1.0], _free(2), reg=1e-9, solver=solver)
    assert weighted.residuals[0] > 0.5  # soft priorities trade the top task away
    # an inequality holds on every level: v1 <= 0.2
    res = solve_cascade([top, low], _free(2, np.array([[1.0, 0.0]]), np.array([0.2])), reg=1e-9, solver=solver)
    np.testing.assert_allclose(res.v, [0.2, 0.8], atol=1e-5)


@pytest.mark.parametrize("seed", range(5))
def test_the_compiled_equality_cascade_matches_the_qp_solver_level_by_level(seed):
    """Random 4-level stacks on 35 velocities (COMAN's size), with and without a least-energy step:
    the compiled path (no inequality active) and daqp solving every level give the same solution;
    with a bound that cuts the optimum, the compiled path hands over and the bound holds."""
    rng = np.random.default_rng(seed)
    n, sizes = 35, [12, 3, 2, 29 if seed % 2 else 10]
    levels = [Level(rng.normal(size=(m, n)), rng.normal(size=m)) for m in sizes]
    metric = None if seed % 2 else (lambda M: M @ M.T + np.eye(n))(rng.normal(size=(n, n)))
    stats: dict = {}
    fast = solve_cascade(levels, _free(n), reg=1e-6, metric=metric, stats=stats)
    assert stats == {"direct": len(levels) + (0 if seed % 2 else 1)}
    # the reference: every level through daqp (an always-active dummy row forces the solver)
    G, h = np.zeros((1, n)), np.zeros(1)
    G[0, 0], h[0] = 1.0, abs(fast.v[0]) + 10.0
    slow_stats: dict = {}
    forced = Inequalities(G, h, np.full(n, -1e9), np.full(n, 1e9))
    from rehabkit.wholebody import stack
    steps = []
    for k, lv in enumerate(levels + ([None] if metric is not None else [])):
        P = metric if lv is None else lv.A.T @ lv.A + 1e-6 * np.eye(n)
        q = np.zeros(n) if lv is None else -lv.A.T @ lv.b
        E = np.vstack([x.A for x in levels[:k]]) if k else None
        e = np.concatenate([x.A @ steps[j] for j, x in enumerate(levels[:k])]) if k else None
        steps.append(stack._solver(P, q, forced, E, e, "daqp", None, slow_stats))
    np.testing.assert_allclose(fast.v, steps[-1], atol=1e-6)
    assert fast.residuals[0] < 1e-5  # the first level (fewer rows than unknowns) is met, up to the damping
    # a bound that the unconstrained optimum breaks: handed to the solver, and it holds
    i = 6 + int(np.argmax(np.abs(fast.v[6:])))
    lb, ub = np.full(n, -1e9), np.full(n, 1e9)
    (ub if fast.v[i] > 0 else lb)[i] = 0.5 * fast.v[i]
    stats = {}
    cut = solve_cascade(levels, Inequalities(np.zeros((0, n)), np.zeros(0), lb, ub), reg=1e-6, metric=metric,
                        stats=stats)
    assert stats.get("solver", 0) >= 1 and not cut.failed_levels
    assert lb[i] - 1e-7 <= cut.v[i] <= ub[i] + 1e-7



def test_the_sparse_kernels_give_the_dense_kernels_results_exactly():
    """Skipping the exact zeros of L leaves every sum as it was: a level's AᵀA + εI (its tasks move 12 of 35)."""
    from rehabkit.numerics import triangular as tri

    rng = np.random.default_rng(1)
    A = np.zeros((12, 35))
    A[:, [*range(6), *range(23, 29)]] = rng.normal(size=(12, 12))
    M = A.T @ A + 1e-6 * np.eye(35)
    L = tri.cholesky(M)
    np.testing.assert_array_equal(tri.cholesky_sparse(M), L)
    B = rng.normal(size=(35, 5))
    np.testing.assert_array_equal(tri.forward_solve_sparse(L, B), tri.forward_solve(L, B))
    np.testing.assert_array_equal(tri.backward_solve_sparse(L, B[:, 0].copy()), tri.backward_solve(L, B[:, 0].copy()))
    assert tri.cholesky_sparse(-M).shape == (0, 0)  # not positive definite

def _stack_config(**extra):
    return QpStackConfig.model_validate({
        "levels": [
            {"name": "feet", "tasks": [{"type": "frame", "frame": "l_sole", "gain": 50},
                                       {"type": "frame", "frame": "r_sole", "gain": 50}]},
            {"name": "hand", "tasks": [{"type": "frame", "frame": "r_hand", "reference": "runner", "gain": 20,
                                        "position_only": True}]},
            {"name": "waist", "tasks": [{"type": "orientation", "frame": "torso", "axes": ["x", "y"], "gain": 10}]},
            {"name": "posture", "tasks": [{"type": "posture", "joints": ARM, "gain": 1, "weight": 0.1},
                                          {"type": "posture", "joints": BODY, "gain": 2}]},
        ],
        "constraints": {"com_height_m": [0.40, 0.60], "support_frames": CORNERS, "support_margin_m": 0.02},
        **extra})


def test_coman_hand_circle_keeps_feet_fixed_and_com_inside():
    robot = ComanRobot(ComanConfig())
    ctx = Context(Path("."), np.random.default_rng(0), 0.001, robot=robot, world=World())
    be = MujocoBackend(MujocoConfig(timestep=0.001), ctx)
    stack = QpStack(_stack_config(), ctx)
    be.reset(robot.standing)
    p0 = robot.fk(robot.standing)[:3, 3]
    feet0 = np.array([be.data.site(s).xpos.copy() for s in ("l_sole", "r_sole")])
    fm = robot.floating_model
    data = fm.createData()
    hand_err, margins, residuals, w = [], [], [], np.pi
    for k in range(3000):
        t = k * 0.001
        x = p0 + 0.08 * np.array([np.sin(w * t), 0, 1 - np.cos(w * t)])
        xd = 0.08 * w * np.array([np.cos(w * t), 0, np.sin(w * t)])
        _, q, qd = be.state()
        be.command(stack.compute(t, q, qd, x, xd, None))
        residuals.append(stack.last_residuals)
        be.step(1)
        pos, quat, _, _ = be.base_state()
        com = pin.centerOfMass(fm, data, robot.pin_configuration(be.state()[1], pos, quat))
        margins.append(stack.constraints.com_margin(com[:2]))
        if k > 500:
            hand_err.append(np.linalg.norm(be.data.site("r_hand").xpos - (robot.model.base_pose[:3, :3] @ x
                                                                          + robot.model.base_pose[:3, 3])))
    feet = np.array([be.data.site(s).xpos for s in ("l_sole", "r_sole")])
    assert np.abs(feet - feet0).max() < 1e-3  # feet fixed (below the contact settling of a millimetre)
    assert max(hand_err) < 0.01  # the hand follows an 8 cm circle at 0.5 Hz
    assert min(margins) > 0.02  # the measured CoM stays inside the support polygon (margin 2 cm)
    m = stack.run_metrics(None)
    assert m["qp_failed_cycles"] == 0 and m["qp_cycles"] == 3000
    # priorities as configured: feet exact, then hand
    res = np.array(residuals)
    assert res[:, 0].max() < 1e-6 and res[500:, 1].max() < 1e-2


def test_a_misspelt_frame_names_the_closest_ones():
    robot = ComanRobot(ComanConfig())
    ctx = Context(Path("."), np.random.default_rng(0), 0.001, robot=robot, world=World())
    cfg = _stack_config().model_dump()
    cfg["levels"][0]["tasks"][0]["frame"] = "l_soel"
    with pytest.raises(ValueError) as unknown:
        QpStack(QpStackConfig.model_validate(cfg), ctx)
    assert suggested(str(unknown.value))[0] == "l_sole"  # (the closest of the model's frames)


def test_tasks_fill_the_stacks_rows_as_they_give_them():
    """The per-cycle path (rows written in place) and the plain one agree, weights included, away from the start."""
    from pydantic import TypeAdapter

    from rehabkit.wholebody.tasks import KinematicState, Task, TaskSpec

    robot = ComanRobot(ComanConfig())
    state = KinematicState(robot.floating_model)
    q = robot.pin_configuration(np.asarray(robot.standing, float))
    state.update(q)
    specs = [{"type": "frame", "frame": "l_sole", "gain": 50, "weight": 2.0},
             {"type": "frame", "frame": "r_hand", "position_only": True, "gain": 30},
             {"type": "orientation", "frame": "Waist", "axes": ["x", "y"], "gain": 10, "weight": 0.5},
             {"type": "posture", "joints": ARM, "gain": 1, "weight": 0.1},
             {"type": "com", "axes": ["x", "y"], "gain": 5}]
    tasks = [Task(TypeAdapter(TaskSpec).validate_python(s), state, robot.model.joint_names) for s in specs]
    moved = q.copy()
    moved[7:] += np.random.default_rng(3).normal(0, 0.1, len(q) - 7)
    moved[3:7] = pin.Quaternion(pin.exp3(np.array([0.05, -0.03, 0.02]))).coeffs()  # the pelvis tilted too
    state.update(moved)
    ref = (np.array([0.3, -0.2, 0.4]), np.array([0.1, 0.0, -0.2]))
    for task in tasks:
        A, b = task.rows(state, ref)
        fa, fb = np.full_like(A, np.nan), np.full_like(b, np.nan)
        if task.spec.type == "posture":
            fa[:] = A  # constant: the stack writes it once
        task.fill(state, ref, fa, fb)
        np.testing.assert_allclose(fa, A, atol=1e-15)
        np.testing.assert_allclose(fb, b, atol=1e-15)
        assert np.abs(b).max() > 1e-3  # an error to correct: the rows are not trivially equal
