"""Closed-loop inverse kinematics to a joint reference, then joint PD (after Loconsole et al., L-Exos).

Each cycle, with the Jacobian J of the hand position at the reference posture q_r:

    q̇_r = J⁺ (ẋ_r + K e) + (I − J⁺ J) q̇_0,   J⁺ = W⁻¹Jᵀ (J W⁻¹ Jᵀ + λ²I)⁻¹,   e = x_r − x(q_r)
    q̇_0 = −k0 ∂w/∂q,   w(q) = Σ (q_i − q_c,i)² / (q_i⁺ − q_i⁻)²

q_r is integrated at the control period and kept inside the joint ranges, and
τ = Kp (q_r − q) + Kv (q̇_r − q̇) [+ gravity by RNEA]. The redundancy is spent
keeping the joints near the middle of their ranges. (The paper writes the
null-space projector with I₃; for n joints it is n×n.) λ is a small damping
that only matters near a singularity (λ = 0 is the paper's exact pseudoinverse).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from pydantic import Field

from rehabkit import hookimpl
from rehabkit.numerics.spd3 import solve_spd3
from rehabkit.plugin import Context, Controller, SettingError, StrictModel


class ClikPDConfig(StrictModel):
    """Gains of the closed-loop IK and of the joint PD."""

    k_task: float = Field(30.0, ge=0, description="K: task-space error gain [1/s]")
    weights: list[float] | None = Field(None, description="W: joint weights (default all 1)")
    k0: float = Field(1.0, ge=0, description="null-space gain toward mid-range")
    damping: float = Field(1e-3, ge=0, description="λ of the damped pseudoinverse [m]")
    kp: float | list[float] = Field(300.0, description="joint stiffness [N·m/rad]")
    kv: float | list[float] = Field(20.0, description="joint damping [N·m·s/rad]")
    gravity_compensation: bool = True


class ClikPD(Controller):
    """Weighted-pseudoinverse closed-loop IK (null space to mid-range) feeding a joint PD."""

    reference = "cartesian"

    def __init__(self, config: ClikPDConfig, context: Context):
        robot = context.robot.model
        n = robot.dof
        self.dt = context.control_dt
        self.model, self.data = robot.pin_model, robot.pin_model.createData()
        self.frame = robot.ee_frame_id
        w = np.ones(n) if config.weights is None else np.asarray(config.weights, float)
        if w.shape != (n,) or np.any(w <= 0):
            raise SettingError("weights", f"must be {n} positive numbers")
        self.w_inv = 1.0 / w
        lim = robot.limits
        self.lower, self.upper, self.vmax = lim.lower, lim.upper, lim.velocity
        self.centre, self.span2 = (lim.lower + lim.upper) / 2, (lim.upper - lim.lower) ** 2
        self.k, self.k0, self.lam2 = config.k_task, config.k0, config.damping**2
        self.kp = np.broadcast_to(np.asarray(config.kp, float), (n,)).copy()
        self.kv = np.broadcast_to(np.asarray(config.kv, float), (n,)).copy()
        self.gravity = config.gravity_compensation
        self.zero = np.zeros(n)
        self.joint_reference: np.ndarray | None = None
        self.qd_r = np.zeros(n)

    def compute(self, t, q, qd, x_r, xd_r, xdd_r):
        if self.joint_reference is None:
            self.joint_reference = q.copy()  # start the integration where the arm is
        q_r = self.joint_reference
        J = pin.computeFrameJacobian(self.model, self.data, q_r, self.frame, pin.LOCAL_WORLD_ALIGNED)[:3]
        e = x_r - self.data.oMf[self.frame].translation
        JW = J * self.w_inv  # J W⁻¹
        qd0 = -self.k0 * 2.0 * (q_r - self.centre) / self.span2
        # J⁺ v + (I − J⁺J) qd0 = qd0 + J⁺ (v − J qd0), with J⁺ = W⁻¹Jᵀ (J W⁻¹ Jᵀ + λ²I)⁻¹: one 3×3 solve
        qd_r = qd0 + JW.T @ solve_spd3(JW @ J.T, xd_r + self.k * e - J @ qd0, self.lam2)
        np.clip(qd_r, -self.vmax, self.vmax, out=qd_r)
        q_r += qd_r * self.dt
        np.clip(q_r, self.lower, self.upper, out=q_r)
        self.qd_r = qd_r
        tau = self.kp * (q_r - q) + self.kv * (qd_r - qd)
        if self.gravity:
            tau += pin.rnea(self.model, self.data, q, self.zero, self.zero)
        return tau


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("clik-pd", config=ClikPDConfig, factory=ClikPD)
