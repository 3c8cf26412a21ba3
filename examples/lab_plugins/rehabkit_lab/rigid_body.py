"""A backend plugin: the robot's rigid-body dynamics alone (Pinocchio's ABA, semi-implicit Euler), no contacts —
a quick stand-in for MuJoCo when a study needs only the arm's own dynamics."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from pydantic import Field

from rehabkit.plugin import Backend, Context, ExternalTorques, Metric, StrictModel, hookimpl


class RigidBodyConfig(StrictModel):
    """The integration step and the joints' viscous friction."""

    timestep: float = Field(0.001, gt=0, le=0.005, description="integration step [s]")
    friction_nms_rad: float = Field(0.05, ge=0, description="viscous friction at every joint [N·m·s/rad]")


class RigidBody(Backend, ExternalTorques):
    """q̈ = ABA(q, q̇, τ + τ_person − b q̇), integrated semi-implicitly (velocity first) each timestep."""

    metrics = (Metric("rigid_body_energy_drift_j", "J", description="largest change of the arm's energy while "
                                                                      "no torque acted (zero when nothing moves)"),)

    def __init__(self, config: RigidBodyConfig, context: Context):
        self.timestep, self.b = config.timestep, config.friction_nms_rad
        self.model = context.robot.model.pin_model
        self.data = self.model.createData()
        n = self.model.nv
        self.t, self.q, self.qd = 0.0, np.zeros(n), np.zeros(n)
        self.tau, self.tau_person = np.zeros(n), np.zeros(n)

    def reset(self, q0):
        self.t, self.q, self.qd = 0.0, np.array(q0, float), np.zeros_like(self.qd)

    def state(self):
        return self.t, self.q, self.qd

    def command(self, tau):
        self.tau = np.array(tau, float)

    def external_torque(self, tau):
        self.tau_person = np.array(tau, float)

    def step(self, n: int = 1):
        for _ in range(n):
            qdd = pin.aba(self.model, self.data, self.q, self.qd, self.tau + self.tau_person - self.b * self.qd)
            self.qd = self.qd + self.timestep * qdd
            self.q = self.q + self.timestep * self.qd
            self.t += self.timestep


@hookimpl
def rehabkit_register_backends(registry) -> None:
    registry.add("rigid-body", config=RigidBodyConfig, factory=RigidBody)
