"""The hand's position and the force at the hand, from a robot's Pinocchio model, for per-step checks."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rehabkit.models.robot_model import RobotModel


class HandForce:
    """The hand force equivalent to joint torques (Jᵀ F = τ, least squares), from the robot's Jacobian."""

    def __init__(self, model: RobotModel):
        import pinocchio as pin

        self._pin = pin
        self.model, self.data, self.frame = model.pin_model, model.pin_model.createData(), model.ee_frame_id
        self.batch = model.batch_fk

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        pin = self._pin
        return pin.computeFrameJacobian(self.model, self.data, q, self.frame, pin.LOCAL_WORLD_ALIGNED)[:3]

    def jacobians(self, qs: np.ndarray) -> np.ndarray:
        """Position Jacobians (N, 3, dof) for the rows of ``qs``, vectorised over the batch."""
        return self.batch.jacobian(qs)

    def __call__(self, q: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Force [N] in the robot base frame's axes (normal equations: a 3×3 solve each control step)."""
        J = self.jacobian(q)
        try:
            return np.linalg.solve(J @ J.T, J @ tau)
        except np.linalg.LinAlgError:  # a singular posture: the minimum-norm least-squares force
            return np.linalg.lstsq(J.T, tau, rcond=None)[0]


def hand_in_world(robot) -> Callable[[np.ndarray], np.ndarray]:
    """``hand(q)``: the hand's world position, for a check every control step. Pinocchio's where it agrees with
    the robot's own kinematics (serial arms: ~2 µs instead of up to ~80 µs), else the robot's (parallel ones)."""
    model = robot.model
    rot, pos = model.base_pose[:3, :3], model.base_pose[:3, 3]
    data = model.new_pin_data()
    samples = np.random.default_rng(0).uniform(model.limits.lower, model.limits.upper, (5, model.dof))
    try:
        agrees = all(np.allclose(robot.fk(q), model.ee_pose(q, data), atol=1e-9) for q in samples)
    except Exception:  # noqa: BLE001 (no usable Pinocchio model: the robot's own kinematics it is)
        agrees = False
    if agrees:
        return lambda q: rot @ model.ee_pose(q, data)[:3, 3] + pos
    return lambda q: robot.ee_world(q[None])[0]
