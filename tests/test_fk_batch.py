"""Whole-run kinematics: every robot's batch forward kinematics equals its own per-sample one, without a Python
loop over the samples."""

from __future__ import annotations

import numpy as np
import pytest

from rehabkit.core.kinds.interfaces import Context, Robot
from rehabkit.core.plugins.registry import default_registry
from tests.conftest import DATA

BUILT_IN = {"hit": {}, "lexos": {}, "arm": {}, "capaman": {}, "coman": {}}


def _robot(name: str, settings: dict) -> Robot:
    info = default_registry().get("robot", name)
    return info.factory(info.config.model_validate({"type": name, **settings}),
                        Context(DATA, np.random.default_rng(0), 0.001))


def _samples(robot: Robot, n: int = 300) -> np.ndarray:
    lim = robot.model.limits
    return np.random.default_rng(7).uniform(lim.lower, lim.upper, (n, robot.model.dof))


@pytest.mark.parametrize("name", sorted(BUILT_IN))
def test_fk_batch_equals_fk_sample_by_sample(name, monkeypatch):
    robot = _robot(name, BUILT_IN[name])
    qs = _samples(robot)
    each = np.stack([robot.fk(q) for q in qs])
    calls = []
    original = robot.fk
    monkeypatch.setattr(robot, "fk", lambda q: calls.append(1) or original(q))  # counts per-sample calls
    batch = robot.fk_batch(qs)
    tol = 1e-9 if name == "capaman" else 1e-12  # CaPaMan's fk is the batch one's first row (numerical closure)
    assert np.abs(batch - each).max() < tol
    assert len(calls) <= 1, f"{name}: fk_batch called fk {len(calls)} times"


@pytest.mark.parametrize(("kind", "settings"), [
    ("urdf", {"file": str(DATA / "arm2.urdf"), "ee_frame": "l2"}),
    ("mjcf", {"file": str(DATA / "arm3.xml"), "ee_frame": "tool", "default_velocity_deg_s": 120}),
])
def test_the_default_batch_is_pinocchio_vectorised(kind, settings):
    """A robot without kinematics of its own (URDF/MJCF): the batch walks Pinocchio's chain with numpy."""
    robot = _robot(kind, settings)
    qs = _samples(robot)
    assert robot.model.batch_fk.vectorised
    pin_each = np.stack([robot.model.ee_pose(q) for q in qs])
    assert np.abs(robot.fk_batch(qs) - pin_each).max() < 1e-12


@pytest.mark.parametrize(("name", "settings"), [("hit", {}), ("lexos", {}), ("arm", {}),
                                                ("urdf", {"file": str(DATA / "arm2.urdf"), "ee_frame": "l2"})])
def test_batch_jacobians_and_gravity_equal_pinocchio_sample_by_sample(name, settings):
    """The outcome measures' hand forces and own-weight torques over a run: batched, the same numbers."""
    import pinocchio as pin

    from rehabkit.models.hand_force import HandForce

    robot = _robot(name, settings)
    qs = _samples(robot)
    m, f = robot.model.pin_model, robot.model.ee_frame_id
    data = m.createData()
    each = np.stack([pin.computeFrameJacobian(m, data, q, f, pin.LOCAL_WORLD_ALIGNED)[:3] for q in qs])
    assert np.abs(HandForce(robot.model).jacobians(qs) - each).max() < 1e-12
    gravity = np.stack([robot.gravity_torque(q) for q in qs])
    assert np.abs(robot.gravity_torques(qs) - gravity).max() < 1e-9 * max(1.0, np.abs(gravity).max())


def test_capaman_gravity_batch_is_its_table_vectorised():
    robot = _robot("capaman", {})
    qs = _samples(robot, 500)
    assert np.abs(robot.gravity_torques(qs) - np.stack([robot.gravity_torque(q) for q in qs])).max() < 1e-12
    # and the table is close to the exact potential gradient (5° grid, trilinear)
    assert np.abs(robot.gravity_torques(qs) - robot.gravity_torque_exact(qs)).max() < 1e-3  # of up to ~0.28 N·m
