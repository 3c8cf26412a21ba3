"""The ARM robot: MANUS kinematics and elbow-up inverse kinematics."""

import numpy as np
import pytest
from rehabkit_plugins.robots.arm import ArmConfig, ArmRobot


@pytest.fixture(scope="module")
def arm():
    return ArmRobot(ArmConfig())


def test_kinematics_match_the_manus_table(arm, rng):
    frames = arm.chain.frames(np.zeros(6))
    upper = frames[2][:3, 3] - frames[1][:3, 3]
    forearm = frames[5][:3, 3] - frames[3][:3, 3]
    assert np.linalg.norm(upper) == pytest.approx(0.3967, abs=1e-9)  # a2; d3 is applied after joint 3
    assert abs(upper[[0, 2]] @ forearm[[0, 2]]) < 1e-12  # q3 = 0: forearm perpendicular to the upper arm
    assert np.linalg.norm(frames[-1][:3, 3] - frames[5][:3, 3]) == pytest.approx(0.12)  # gripper
    lim = arm.model.limits
    for q in rng.uniform(lim.lower, lim.upper, (50, 6)):
        np.testing.assert_allclose(arm.model.ee_pose(q), arm.fk(q), atol=1e-12)  # Pinocchio = MDH chain


def test_elbow_up_ik_round_trip(arm, rng):
    lim = arm.model.limits
    solved = 0
    for q in rng.uniform(lim.lower, lim.upper, (30, 6)):
        if not arm.elbow_up(q):
            continue
        sols = arm.ik(arm.fk(q))
        assert sols, np.degrees(q)
        for s in sols:
            np.testing.assert_allclose(arm.fk(s), arm.fk(q), atol=1e-8)
            assert arm.elbow_up(s)
        solved += 1
    assert solved >= 10
