"""The hand's position and the force at the hand, from a robot's Pinocchio model, for per-step checks."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rehabkit.models.robot_model import RobotModel
from rehabkit.numerics.spd3 import solve_spd3

DAMPING_M = 0.02  # damped least squares: near a straight arm the plain one grows without bound


def hand_forces(J: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Hand forces F with Jᵀ F = τ in the damped least-squares sense, F = (J Jᵀ + λ² I)⁻¹ J τ, for position
    Jacobians J (..., 3, dof) and torques (..., dof). A person's torques reach the robot through cuffs along the
    arm, not the hand alone: near a singular posture (the elbow straight) the plain least-squares force would grow
    without bound for torques the cuffs carry; λ = 2 cm leaves it within 0.5 % of it wherever the Jacobian's
    smallest singular value is above 0.3 m."""
    J = np.asarray(J, float)
    JJt = J @ np.swapaxes(J, -1, -2) + DAMPING_M**2 * np.eye(3)
    return np.linalg.solve(JJt, (J @ np.asarray(tau, float)[..., None]))[..., 0]


def least_wrenches(model, qs: np.ndarray, taus: np.ndarray, frame: int) -> np.ndarray:
    """The least wrench (force, torque: (n, 6)) at Pinocchio ``model``'s ``frame``, in its own axes, whose joint
    torques are ``taus`` at postures ``qs`` (Jᵀ w = τ, J the frame's Jacobian): what a six-axis sensor there
    measures of a person's torques."""
    import pinocchio as pin

    data = model.createData()
    taus = np.asarray(taus, float).reshape(len(qs), -1)
    out = np.zeros((len(qs), 6))
    for k in range(len(qs)):  # (a one-joint robot's Jacobian comes from Pinocchio as a vector: a 6×1 column here)
        J = pin.computeFrameJacobian(model, data, qs[k], frame, pin.LOCAL).reshape(6, -1)
        out[k] = J @ np.linalg.lstsq(J.T @ J, taus[k], rcond=None)[0]
    return out


class HandForce:
    """The hand force equivalent to joint torques (Jᵀ F = τ, damped least squares), from the robot's Jacobian."""

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
        """Force [N] in the robot base frame's axes (a 3×3 solve each control step)."""
        J = self.jacobian(q)
        return solve_spd3(J @ J.T, J @ tau, DAMPING_M**2)


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
