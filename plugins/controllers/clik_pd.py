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
from numba import njit
from pydantic import Field

from rehabkit.control import adjugate_solve3
from rehabkit.plugin import Context, Controller, SettingError, StrictModel, hookimpl

_solve3 = njit(cache=True, nogil=True)(adjugate_solve3)


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
        self.joint_reference: np.ndarray | None = None
        self.qd_r = np.zeros(n)

    def compute(self, t, q, qd, x_r, xd_r, xdd_r):
        if self.joint_reference is None:
            self.joint_reference = q.copy()  # start the integration where the arm is
        q_r = self.joint_reference
        J = pin.computeFrameJacobian(self.model, self.data, q_r, self.frame, pin.LOCAL_WORLD_ALIGNED)
        self.qd_r, tau = _clik_step(J, self.data.oMf[self.frame].translation, x_r, xd_r, q_r, q, qd, self.w_inv,
                                    self.centre, self.span2, self.vmax, self.lower, self.upper, self.kp, self.kv,
                                    self.k, self.k0, self.lam2, self.dt)
        if self.gravity:
            tau += pin.computeGeneralizedGravity(self.model, self.data, q)  # (RNEA at rest)
        return tau


@njit(cache=True, nogil=True)
def _clik_step(J, x, x_r, xd_r, q_r, q, qd, w_inv, centre, span2, vmax, lower, upper, kp, kv, k, k0, lam2,
               dt):  # pragma: no cover - compiled
    """One cycle of the module docstring's law, compiled (numpy's per-call dispatch on 3×n matrices costs more than
    the arithmetic): q̇_r and the PD torque; q_r advanced in place. ``J``: the frame Jacobian (rows 0–2 used),
    ``x``: the hand position at q_r."""
    n = len(q_r)
    qd0, JW, v = np.empty(n), np.empty((3, n)), np.empty(3)
    for j in range(n):
        qd0[j] = -k0 * 2.0 * (q_r[j] - centre[j]) / span2[j]
    for i in range(3):
        Jqd0 = 0.0
        for j in range(n):
            JW[i, j] = J[i, j] * w_inv[j]  # J W⁻¹
            Jqd0 += J[i, j] * qd0[j]
        v[i] = xd_r[i] + k * (x_r[i] - x[i]) - Jqd0
    A = np.zeros((3, 3))  # J W⁻¹ Jᵀ, its upper triangle
    for i in range(3):
        for m in range(i, 3):
            for j in range(n):
                A[i, m] += JW[i, j] * J[m, j]
    # J⁺ v + (I − J⁺J) qd0 = qd0 + J⁺ (v − J qd0), with J⁺ = W⁻¹Jᵀ (J W⁻¹ Jᵀ + λ²I)⁻¹: one 3×3 solve
    s0, s1, s2 = _solve3(A[0, 0] + lam2, A[0, 1], A[0, 2], A[1, 1] + lam2, A[1, 2], A[2, 2] + lam2, v[0], v[1], v[2])
    qd_r, tau = np.empty(n), np.empty(n)
    for j in range(n):
        qd_r[j] = min(max(qd0[j] + (JW[0, j] * s0 + JW[1, j] * s1 + JW[2, j] * s2), -vmax[j]), vmax[j])
        q_r[j] = min(max(q_r[j] + qd_r[j] * dt, lower[j]), upper[j])
        tau[j] = kp[j] * (q_r[j] - q[j]) + kv[j] * (qd_r[j] - qd[j])
    return qd_r, tau


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("clik-pd", config=ClikPDConfig, factory=ClikPD)
