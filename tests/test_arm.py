"""The ARM robot: MANUS kinematics, lift and gripper, closed-form elbow-up inverse kinematics."""

import mujoco
import numpy as np
import pytest
from rehabkit_plugins.robots.arm import ArmConfig, ArmRobot

from rehabkit.core.scenario.models import World
from rehabkit.sim.scene import build_scene


@pytest.fixture(scope="module")
def arm():
    return ArmRobot(ArmConfig())


def test_kinematics_match_the_manus_table(arm, rng):
    assert arm.model.joint_names == ["lift", "j1", "j2", "j3", "j4", "j5", "j6", "gripper"]  # 6 + gripper + lift
    frames = arm.chain.frames(np.zeros(7))
    upper = frames[3][:3, 3] - frames[2][:3, 3]
    forearm = frames[6][:3, 3] - frames[4][:3, 3]
    assert np.linalg.norm(upper) == pytest.approx(0.3967, abs=1e-9)  # a2; d3 is applied after joint 3
    assert abs(upper[[0, 2]] @ forearm[[0, 2]]) < 1e-12  # q3 = 0: forearm perpendicular to the upper arm
    assert np.linalg.norm(frames[-1][:3, 3] - frames[6][:3, 3]) == pytest.approx(0.12)  # gripper
    up = np.zeros(8)
    up[0] = 0.25
    np.testing.assert_allclose(arm.fk(up)[:3, 3] - arm.fk(np.zeros(8))[:3, 3], [0, 0, 0.25], atol=1e-12)  # lift
    lim = arm.model.limits
    for q in rng.uniform(lim.lower, lim.upper, (50, 8)):
        np.testing.assert_allclose(arm.model.ee_pose(q), arm.fk(q), atol=1e-12)  # Pinocchio = MDH chain


def test_closed_form_ik_recovers_every_elbow_up_configuration(arm, rng):
    lim = arm.model.limits
    solved = 0
    for q in rng.uniform(lim.lower, lim.upper, (400, 8)):
        if not arm.elbow_up(q):
            continue
        sols = arm.ik(arm.fk(q), reference=q)
        assert sols, np.degrees(q)
        np.testing.assert_allclose(sols[0], q, atol=1e-7)  # nearest the reference comes first
        for s in sols:
            np.testing.assert_allclose(arm.fk(s), arm.fk(q), atol=1e-9)
            assert arm.elbow_up(s)
            assert np.all(s >= lim.lower) and np.all(s <= lim.upper)
        solved += 1
    assert solved >= 150


def test_elbow_up_means_the_elbow_above_the_shoulder_wrist_line(arm):
    q = np.radians([0, 0, -60, 30, 0, 60, 0, 0])
    q[0] = 0.0
    frames = arm.chain.frames(q[:7])
    shoulder, elbow, wrist = frames[2][:3, 3], frames[3][:3, 3], frames[6][:3, 3]
    s = (elbow - shoulder) @ (wrist - shoulder) / np.linalg.norm(wrist - shoulder) ** 2
    assert arm.elbow_up(q) == (elbow[2] > shoulder[2] + s * (wrist - shoulder)[2])
    sols = arm.ik(arm.fk(q))
    assert sols and all(arm.elbow_up(x) for x in sols)


def test_fingers_open_symmetrically_in_mujoco(arm):
    spec = build_scene(arm.model, World(), 0.002)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[model.joint("gripper").qposadr[0]] = 0.03
    for _ in range(2000):  # the equality constraint pulls the mirror finger to the same opening
        mujoco.mj_step(model, data)
        data.qfrc_applied[model.joint("gripper").dofadr[0]] = 5.0  # opening force against the damping
    a = data.geom("gripper_pad").xpos
    b = data.geom("gripper_mirror_pad").xpos
    assert data.qpos[model.joint("gripper_mirror").qposadr[0]] == pytest.approx(
        data.qpos[model.joint("gripper").qposadr[0]], abs=1e-3)
    assert np.linalg.norm(a - b) > 0.05  # open: fingers well apart
