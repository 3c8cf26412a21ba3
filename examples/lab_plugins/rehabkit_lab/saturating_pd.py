"""A controller plugin: joint PD whose correction saturates smoothly (tanh) at a torque budget, plus gravity."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, Controller, Metric, StrictModel, hookimpl


class SaturatingPDConfig(StrictModel):
    """Gains and the correction's budget."""

    kp: float = Field(200.0, gt=0, description="stiffness [N·m/rad]")
    kd: float = Field(10.0, ge=0, description="damping [N·m·s/rad]")
    budget_nm: float = Field(15.0, gt=0, description="largest PD correction per joint [N·m] (gravity comes on top)")


class SaturatingPD(Controller):
    """τ = budget · tanh((kp·e + kd·ė) / budget) + g(q): gentle far from the reference, a PD near it."""

    metrics = (Metric("pd_saturated_share", description="share of control steps with a correction above 90% of "
                                                         "the budget"),)

    def __init__(self, config: SaturatingPDConfig, context: Context):
        self.config, self.gravity = config, context.robot.gravity_torque
        self.steps = self.saturated = 0

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        c = self.config
        pd = c.kp * (q_ref - q) + c.kd * (qd_ref - qd)
        self.steps += 1
        self.saturated += bool(np.any(np.abs(pd) > 0.9 * c.budget_nm))  # (tanh(1.47) = 0.9)
        return c.budget_nm * np.tanh(pd / c.budget_nm) + self.gravity(q)

    def run_metrics(self, trace) -> dict[str, float]:
        return {"pd_saturated_share": self.saturated / max(1, self.steps)}


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("saturating-pd", config=SaturatingPDConfig, factory=SaturatingPD)
