"""COMAN: the converted model, its floating base, and standing on both feet in MuJoCo."""

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from rehabkit_plugins.robots.coman import ComanConfig, ComanRobot

from rehabkit.core.kinds.interfaces import Context
from rehabkit.core.scenario.models import World
from rehabkit.sim.mujoco import MujocoBackend, MujocoConfig


@pytest.fixture(scope="module")
def coman():
    return ComanRobot(ComanConfig())


def _backend(robot, world=None):
    ctx = Context(Path("."), np.random.default_rng(0), 0.001, robot=robot, world=world or World())
    return MujocoBackend(MujocoConfig(timestep=0.001), ctx)


def test_model_matches_the_public_urdf_facts(coman):
    m = coman.model
    assert m.dof == 29 and m.floating
    assert sum(n.startswith(("RHip", "RKnee", "RAnk")) for n in m.joint_names) == 6
    assert sum(n.startswith(("RSh", "RElb", "RForearm", "RWr")) for n in m.joint_names) == 7
    fm = coman.floating_model
    assert pin.computeTotalMass(fm) == pytest.approx(31.46, abs=0.01)  # URDF without the head camera
    axis = mujoco.MjModel.from_xml_string(m.mjcf).joint("WaistLat").axis
    np.testing.assert_allclose(axis, [np.cos(np.radians(20)), 0, np.sin(np.radians(20))], atol=1e-6)  # tilted 20°
    # standing posture: soles flat, 14.5 cm apart
    be = _backend(coman)
    be.reset(coman.standing)
    left, right = be.data.site("l_sole").xpos, be.data.site("r_sole").xpos
    assert np.linalg.norm(left - right) == pytest.approx(0.1452, abs=1e-3)
    assert be.contacts() == []  # feet on the floor are support, not collisions
    assert be.data.ncon == 8  # four corners of each sole box


def test_pinocchio_and_mujoco_agree_with_a_moving_pelvis(coman, rng):
    fm, be = coman.floating_model, _backend(coman)
    data = fm.createData()
    lim = coman.model.limits
    for _ in range(20):
        q = rng.uniform(lim.lower, lim.upper)
        pos, quat = rng.normal(size=3), rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        be.reset(q)
        adr = be.model.jnt_qposadr[be._root_joint]
        be.data.qpos[adr : adr + 7] = [*pos, *quat]
        mujoco.mj_forward(be.model, be.data)
        qf = coman.pin_configuration(q, pos, quat)
        pin.framesForwardKinematics(fm, data, qf)
        for site in ("r_hand", "l_sole", "torso"):
            np.testing.assert_allclose(data.oMf[fm.getFrameId(site)].translation, be.data.site(site).xpos, atol=1e-9)
        got = be.base_state()
        np.testing.assert_allclose(got[0], pos) and np.testing.assert_allclose(got[1], quat)


def test_support_torques_hold_the_standing_robot(coman):
    be = _backend(coman)
    be.reset(coman.standing)
    feet0 = np.array([be.data.site(s).xpos.copy() for s in ("l_sole", "r_sole")])
    for _ in range(2000):
        _, q, qd = be.state()
        pos, quat, _, _ = be.base_state()
        tau = 300 * (coman.standing - q) - 5 * qd + coman.support_torque(coman.pin_configuration(q, pos, quat))
        be.command(tau)
        be.step(1)
    feet = np.array([be.data.site(s).xpos for s in ("l_sole", "r_sole")])
    assert np.abs(feet - feet0).max() < 1e-3  # no slip
    assert abs(be.base_state()[0][2] - coman.model.base_pose[2, 3]) < 2e-3  # pelvis height kept (contact settling)
    # soft joints with the pelvis-fixed gravity model instead (each limb holds only itself): the legs give way
    model, data, zero = coman.model.pin_model, coman.model.new_pin_data(), np.zeros(29)
    be.reset(coman.standing)
    for _ in range(2000):
        _, q, qd = be.state()
        be.command(30 * (coman.standing - q) - 1 * qd + pin.rnea(model, data, q, zero, zero))
        be.step(1)
    assert be.base_state()[0][2] < coman.model.base_pose[2, 3] - 0.01
