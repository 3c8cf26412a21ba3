"""Throws: the swing model, LWLR, the retargeted library and generator, and a ball held then released."""

from pathlib import Path

import numpy as np
import pytest
from rehabkit_plugins.planners.throw_lwlr import ThrowConfig, ThrowPlanner
from rehabkit_plugins.robots.coman import ComanConfig, ComanRobot

from rehabkit.core.kinds.interfaces import Context
from rehabkit.core.scenario.models import World
from rehabkit.sim.mujoco import MujocoBackend, MujocoConfig
from rehabkit.throwing.lwlr import LWLR
from rehabkit.throwing.model import Throw, hand_path, parabola, plane_crossing, swing_angle

THROW = Throw(back=-0.45, release=0.7, t_back=0.45, t_fwd=0.55, omega=3.0, radius=0.4, aim=0.05)


@pytest.fixture(scope="module")
def coman():
    return ComanRobot(ComanConfig())


@pytest.fixture(scope="module")
def planner(coman):
    return ThrowPlanner(ThrowConfig(), Context(Path("."), np.random.default_rng(0), 0.001, robot=coman))


def test_swing_reaches_the_release_with_the_planned_speed():
    phi, dphi, ddphi = swing_angle(THROW, np.array([0.0, THROW.t_back, THROW.release_time]))
    np.testing.assert_allclose(phi, [0.0, THROW.back, THROW.release], atol=1e-12)
    np.testing.assert_allclose(dphi, [0.0, 0.0, THROW.omega], atol=1e-12)
    assert ddphi[2] == pytest.approx(0.0, abs=1e-9)  # released without a jerk in the arm
    t = np.linspace(0, THROW.release_time, 2001)
    p, v, a = hand_path(THROW, np.zeros(3), t)
    # v is dp/dt and a is dv/dt (away from the phase change, where the jerk steps and differences blur)
    inner = (np.abs(t - THROW.t_back) > 0.005) & (t > 0.005) & (t < t[-1] - 0.005)
    np.testing.assert_allclose(np.gradient(p, t, axis=0)[inner], v[inner], atol=2e-4)
    np.testing.assert_allclose(np.gradient(v, t, axis=0)[inner], a[inner], atol=2e-3)
    assert np.linalg.norm(v[-1]) == pytest.approx(THROW.omega * THROW.radius)


def test_ballistics_cross_the_plane_where_the_parabola_says():
    p0, v0 = np.array([0.2, -0.1, 0.6]), np.array([1.0, 0.1, 1.5])
    hit, t = plane_crossing(p0, v0, 0.7)
    assert t == pytest.approx(0.5)
    np.testing.assert_allclose(hit, [0.7, -0.05, 0.6 + 0.75 - 0.5 * 9.81 * 0.25])
    np.testing.assert_allclose(parabola(p0, v0, np.array([t]))[0], hit)
    assert plane_crossing(p0, -v0, 0.7) is None


def test_lwlr_is_exact_on_linear_data_and_local_on_curved_data(rng):
    x = rng.uniform(-1, 1, (60, 2))
    y = np.column_stack([2 * x[:, 0] - x[:, 1] + 0.5, x[:, 1]])
    np.testing.assert_allclose(LWLR(x, y).predict(np.array([0.3, -0.2])), [1.3, -0.2], atol=1e-5)
    curved = np.sin(3 * x[:, :1]) + x[:, 1:] ** 2
    query = np.array([0.4, 0.5])
    truth = np.sin(1.2) + 0.25
    local = abs(LWLR(x, curved, bandwidth=0.3).predict(query)[0] - truth)
    glob = abs(LWLR(x, curved, bandwidth=1e3).predict(query)[0] - truth)  # a huge bandwidth: one global plane
    assert local < 0.05 and local < glob / 3


def test_library_is_retargeted_and_feasible(planner, coman):
    assert len(planner.library) == 30 and len(planner.feasible) >= 25
    assert planner.scale == pytest.approx(planner.arm_length / 0.68)
    human, robot = planner.human[0], planner.library[0]
    assert robot.release_time == human.release_time and robot.omega == human.omega  # timing kept
    assert robot.radius == pytest.approx(human.radius * planner.scale)  # geometry (and so speed) scaled


def test_generated_throws_land_where_asked(planner, rng):
    _, outcomes = planner._model(0.5)
    lo, hi = np.percentile(outcomes, [20, 80], axis=0)
    errors = []
    for _ in range(20):
        catch = np.array([0.5, *rng.uniform(lo, hi)])
        _, predicted = planner.generate(catch)
        errors.append(np.linalg.norm(predicted - catch))
    assert np.median(errors) < 0.01 and max(errors) < 0.03  # LWLR inverse over the demonstrated region


def test_a_held_ball_stays_in_the_hand_then_flies_free(coman):
    world = World.model_validate({"objects": [{"name": "ball", "shape": "sphere", "size": [0.03], "dynamic": True,
                                               "mass": 0.06, "held_by": "r_hand"}]})
    be = MujocoBackend(MujocoConfig(timestep=0.001),
                       Context(Path("."), np.random.default_rng(0), 0.001, robot=coman, world=world))
    be.reset(coman.standing)
    hold = lambda q, qd: 300 * (coman.standing - q) - 5 * qd + coman.gravity_torque(q)  # noqa: E731
    for _ in range(300):
        _, q, qd = be.state()
        be.command(hold(q, qd))
        be.step(1)
    assert np.linalg.norm(be.object_position("ball") - be.ee_position()) < 1e-3
    assert be.contacts() == []  # the hand does not collide with what it carries
    be.release("ball")
    p0 = be.object_position("ball")
    for _ in range(200):
        be.step(1)
    drop = p0[2] - be.object_position("ball")[2]
    assert drop == pytest.approx(0.5 * 9.81 * 0.2**2, rel=0.02)  # free fall from rest
    be.grasp("ball")
    assert np.linalg.norm(be.object_position("ball") - be.ee_position()) < 1e-6
    with pytest.raises(ValueError, match="not a held object"):
        be.release("cup")
