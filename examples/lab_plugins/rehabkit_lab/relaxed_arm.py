"""A patient plugin: a relaxed arm strapped to the robot — passive stiffness and damping about a rest posture."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, Metric, Patient, SettingError, StrictModel, hookimpl


class RelaxedArmConfig(StrictModel):
    """The arm's passive tissue."""

    stiffness_nm_rad: float = Field(3.0, ge=0, description="passive stiffness [N·m/rad]")
    damping_nms_rad: float = Field(0.5, ge=0, description="passive damping [N·m·s/rad]")
    rest_deg: list[float] | None = Field(None, description="rest posture (default: where the arm starts)")


class RelaxedArm(Patient):
    """τ = −k (q − rest) − d q̇: a person who lets the robot move them."""

    metrics = (Metric("person_torque_max_nm", "N·m", description="largest torque the arm put on a joint"),)

    def __init__(self, config: RelaxedArmConfig, context: Context):
        self.config, self.rest, self.peak = config, None, 0.0
        if config.rest_deg is not None:
            self.rest = np.radians(config.rest_deg)
            if len(self.rest) != context.robot.model.dof:
                raise SettingError("rest_deg", f"has {len(self.rest)} values; the robot has "
                                               f"{context.robot.model.dof} joints")

    def torque(self, t, q, qd, goal):
        if self.rest is None:
            self.rest = np.array(q, float)
        tau = -self.config.stiffness_nm_rad * (q - self.rest) - self.config.damping_nms_rad * qd
        self.peak = max(self.peak, float(np.abs(tau).max()))
        return tau

    def run_metrics(self, trace) -> dict[str, float]:
        return {"person_torque_max_nm": self.peak}


@hookimpl
def rehabkit_register_patients(registry) -> None:
    registry.add("relaxed-arm", config=RelaxedArmConfig, factory=RelaxedArm)
