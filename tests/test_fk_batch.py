"""Whole-run kinematics: every robot's batch forward kinematics equals its own per-sample one, without a Python
loop over the samples."""

from __future__ import annotations

import numpy as np
import pytest

from rehabkit.core.interfaces import Context, Robot
from rehabkit.core.plugins import default_registry
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
