"""Static optimisation: the muscle activations that make a joint torque at least effort.

Each muscle's force is MuJoCo's Hill-type model, linear in its activation a at the present length l and
lengthening speed v: F = F₀ c · FL(l) FV(v) · a + F₀ FP(l) (the passive part), pulling along its path; the joint
torques are its moment arms times that force. Given the torques τ the person wants at the driven joints,

    minimise Σ aᵢ²   subject to   Cᵀ Rᵀ (g ⊙ a + p) = τ,   0 ≤ a ≤ 1

(R the moment arms, g and p the active gains and passive forces, C the driven joints' coupling), solved with
qpsolvers. A torque beyond the muscles' capacity has no solution: then the activations giving the nearest
torque (least squares, within the bounds) are used and the step is reported as saturated.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import qpsolvers

from rehabkit.musculo.human import HumanArm
from rehabkit.numerics.indices import span

TOLERANCE_NM = 1e-3  # a torque met within this is reproduced; beyond it the step is saturated
EFFORT_WEIGHT = 1e-4  # the least-squares fallback's pull toward low activations (per N·m² of torque error)


@dataclass
class Solution:
    """Activations, the torque they give at the driven joints [N·m], and whether the request was beyond reach."""

    activation: np.ndarray
    torque: np.ndarray
    saturated: bool

    @property
    def effort(self) -> float:
        """Σ a², the criterion."""
        return float(self.activation @ self.activation)


class StaticOptimisation:
    """Per control step: :meth:`matrices` from the arm's present state, then :meth:`solve` for a torque."""

    def __init__(self, arm: HumanArm, solver: str = "daqp"):
        self.arm, self.solver = arm, solver
        # the solver's own qpsolvers entry point: solve_qp's problem checks cost as much as the solve here
        self._solve = getattr(qpsolvers, f"{solver}_solve_qp")
        m = arm.model
        self._moment = np.zeros((m.nu, m.nv))
        self._n = len(arm.muscles)
        self._P = 2.0 * np.eye(self._n)
        self._zero = np.zeros(self._n)
        self._lb, self._ub = np.zeros(self._n), np.ones(self._n)
        self._act = span(m.actuator_actadr[arm.all_muscles])  # activation states of every muscle of the arm
        self.act_of_muscles = span(m.actuator_actadr[arm.muscles])  # those of the optimised muscles, in order

    def matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, τ_passive): the driven joints' torque is A a + τ_passive at the present state."""
        arm, d = self.arm, self.arm.data
        mujoco.mju_sparse2dense(self._moment, d.actuator_moment, d.moment_rownnz, d.moment_rowadr, d.moment_colind)
        # MuJoCo's own muscle forces at activation 0 (the passive part) and 1 (plus the active gain), from the
        # lengths and speeds of the last step: one C call each instead of one per muscle
        m, act, saved = arm.model, d.act, d.act[self._act].copy()
        act[self._act] = 0.0
        mujoco.mj_fwdActuation(m, d)
        bias = d.actuator_force[arm.muscle_span].copy()
        act[self._act] = 1.0
        mujoco.mj_fwdActuation(m, d)
        gain = d.actuator_force[arm.muscle_span] - bias
        act[self._act] = saved  # (the forces themselves are recomputed by the next step)
        arms = self._moment[arm.muscle_span] @ arm.coupling_matrix()  # muscles × driven joints
        return arms.T * gain, arms.T @ bias

    def solve(self, tau: np.ndarray, A: np.ndarray | None = None, passive: np.ndarray | None = None) -> Solution:
        """The least-effort activations giving ``tau`` at the driven joints (or the nearest they can give)."""
        if A is None or passive is None:
            A, passive = self.matrices()
        rhs = np.asarray(tau, float) - passive
        a = self._solve(self._P, self._zero, None, None, A, rhs, self._lb, self._ub)
        if a is not None and np.max(np.abs(A @ a - rhs)) <= TOLERANCE_NM:
            return Solution(np.clip(a, 0.0, 1.0), A @ a + passive, False)
        # beyond reach: the nearest torque the muscles can give, a little effort weight to make it unique
        P = 2.0 * (A.T @ A + EFFORT_WEIGHT * np.eye(self._n))
        a = self._solve(P, -2.0 * A.T @ rhs, None, None, None, None, self._lb, self._ub)
        a = np.clip(a if a is not None else self._zero, 0.0, 1.0)
        return Solution(a, A @ a + passive, True)
