"""Joint-space PD with model-based feedforward from Pinocchio."""

from __future__ import annotations

from typing import Literal

import numpy as np
import pinocchio as pin
from pydantic import Field

from rehabkit import hookimpl
from rehabkit.core.interfaces import Context, Controller, StrictModel


class JointPDConfig(StrictModel):
    """Gains per joint (a list) or for all joints (one number)."""

    kp: float | list[float] = Field(100.0, description="stiffness [N·m/rad]")
    kd: float | list[float] = Field(10.0, description="damping [N·m·s/rad]")
    feedforward: Literal["gravity", "inverse-dynamics", "none"] = Field(
        "gravity", description="gravity: RNEA(q, 0, 0); inverse-dynamics: RNEA(q, qd_ref, qdd_ref)"
    )


class JointPD(Controller):
    """Joint PD, τ = Kp(q_ref − q) + Kd(q̇_ref − q̇) + RNEA feedforward."""

    def __init__(self, config: JointPDConfig, context: Context):
        model = context.robot.model
        n = model.dof
        self.kp = self._gains(config.kp, n, "kp")
        self.kd = self._gains(config.kd, n, "kd")
        self.mode = config.feedforward
        self._inverse_dynamics, self._gravity = self.mode == "inverse-dynamics", self.mode == "gravity"
        self._gravity_torque = context.robot.gravity_torque  # the robot's own model (Pinocchio for serial arms)
        if self._inverse_dynamics:
            self._model = model.pin_model
            self._data = self._model.createData()

    @staticmethod
    def _gains(value: float | list[float], n: int, name: str) -> np.ndarray:
        g = np.full(n, float(value)) if isinstance(value, (int, float)) else np.asarray(value, dtype=float)
        if g.shape != (n,):
            raise ValueError(f"joint-pd: {name} has {g.size} values; the robot has {n} joints")
        if np.any(g < 0):
            raise ValueError(f"joint-pd: {name} must be >= 0")
        return g

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        tau = self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
        if self._inverse_dynamics:
            tau += pin.rnea(self._model, self._data, q, qd_ref, qdd_ref)
        elif self._gravity:
            tau += self._gravity_torque(q)
        return tau


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("joint-pd", config=JointPDConfig, factory=JointPD)
