"""Every robot offers its kinematics and dynamics through the same methods — poses of its bodies, Jacobians, the
mass matrix, gravity — built-in, analytic, from files and parallel alike; none raises on one robot and not another.
Checked against finite differences of the robot's own forward kinematics and against MuJoCo's dynamics."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.plugin import PassiveJoints
from rehabkit.sim.scene import couple_joints
from tests.conftest import SCENARIOS

ROBOTS = {"hit": "hit_roundtrip.yaml", "lexos": "lexos_reaching.yaml", "arm": "arm_replay.yaml",
          "coman": "coman_juggling.yaml", "capaman": "capaman_obstacle.yaml",
          "dh": "../examples/robots/dh_arm3.yaml", "urdf": "../examples/robots/urdf_arm4.yaml",
          "mjcf": "../examples/robots/mjcf_arm5.yaml"}


@pytest.fixture(scope="module", params=sorted(ROBOTS))
def robot(request):
    return Runner(load_scenario(SCENARIOS / ROBOTS[request.param], {"backend.type": "mujoco"})).build(
    ).robot


def _configurations(robot, n=4):
    lim = robot.model.limits
    lo, hi = np.maximum(lim.lower, -np.pi), np.minimum(lim.upper, np.pi)
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    return mid + 0.6 * half * np.random.default_rng(3).uniform(-1, 1, (n, robot.model.dof))


def _rotation_rate(R0: np.ndarray, R1: np.ndarray, dt: float) -> np.ndarray:
    """ω with R1 ≈ exp([ω] dt) R0 (base-frame axes)."""
    W = (R1 @ R0.T - (R1 @ R0.T).T) / (2 * dt)  # (first order: the antisymmetric part)
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


def test_the_jacobian_is_the_derivative_of_the_robots_own_forward_kinematics(robot):
    eps = 1e-6
    for q in _configurations(robot):
        J = robot.jacobian(q)
        assert J.shape == (6, robot.model.dof)
        for j in range(robot.model.dof):
            dq = np.zeros(robot.model.dof)
            dq[j] = eps
            plus, minus = robot.fk(q + dq), robot.fk(q - dq)
            np.testing.assert_allclose(J[:3, j], (plus[:3, 3] - minus[:3, 3]) / (2 * eps), atol=1e-6)
            np.testing.assert_allclose(J[3:, j], _rotation_rate(minus[:3, :3], plus[:3, :3], 2 * eps), atol=1e-6)


def test_the_hands_body_pose_is_the_forward_kinematics(robot):
    qs = _configurations(robot)
    p, R = robot.body_poses(robot.model.ee_site, qs)
    for q, pi, Ri in zip(qs, p, R):
        T = robot.fk(q)
        np.testing.assert_allclose(pi, T[:3, 3], atol=1e-9)
        np.testing.assert_allclose(Ri, T[:3, :3], atol=1e-9)
    with pytest.raises(ValueError, match="no body or site 'elbw'|predicts the poses of"):
        robot.body_poses("elbw", qs)


def test_the_mass_matrix_is_mujocos(robot):
    """A serial robot's M(q) is MuJoCo's joint-space inertia at q (a floating one's: the block of its joints); a
    parallel robot's cranks' M moves them as MuJoCo does through its closed loops: from rest, without gravity,
    torques τ give the accelerations M⁻¹τ (MuJoCo's loops are soft constraints: within 10 %)."""
    mj = mujoco.MjModel.from_xml_string(robot.model.mjcf)
    mj.opt.gravity[:] = 0
    d = mujoco.MjData(mj)
    names = robot.model.joint_names
    dofs = [mj.jnt_dofadr[mj.joint(n).id] for n in names]
    for q in _configurations(robot, 2):
        M = robot.mass_matrix(q)
        assert np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() > 0
        mujoco.mj_resetData(mj, d)
        state = dict(zip(names, q[:, None]))
        if isinstance(robot, PassiveJoints):
            state.update(robot.passive_state(q))
        for name, value in state.items():
            adr = mj.jnt_qposadr[mj.joint(name).id]
            d.qpos[adr:adr + len(value)] = value
        if not isinstance(robot, PassiveJoints):
            couple_joints(mj, d)  # (a follower — ARM's second finger — where its leader puts it)
            mujoco.mj_forward(mj, d)
            full = np.zeros((mj.nv, mj.nv))
            mujoco.mj_fullM(mj, d, full)
            # the joints' inertia as they move: a follower moves with its leader (q_f = offset + scale·q_l), so
            # its inertia is its leader's to carry: Gᵀ M G, G the velocities of every dof per joint's speed
            G = np.zeros((mj.nv, len(names)))
            G[dofs, range(len(names))] = 1.0
            for follower, (leader, _, scale) in robot.model.couplings.items():
                G[mj.jnt_dofadr[mj.joint(follower).id], names.index(leader)] = scale
            np.testing.assert_allclose(M, G.T @ full @ G, atol=1e-9)
            continue
        tau = np.array([0.01, -0.02, 0.015])
        d.qfrc_applied[dofs] = tau
        mujoco.mj_forward(mj, d)
        np.testing.assert_allclose(d.qacc[dofs], np.linalg.solve(M, tau), rtol=0.1)
