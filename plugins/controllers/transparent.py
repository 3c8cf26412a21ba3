"""A transparent robot: gravity and the joints' friction compensated, no stiffness — the person moves it, as in
the active part of a range-of-motion assessment. The reference is ignored (the planner's goals are the cues the
person is given)."""

from __future__ import annotations

import mujoco
import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, Controller, StrictModel, hookimpl


class TransparentConfig(StrictModel):
    """How much of the robot's own resistance to take away."""

    gravity: bool = Field(True, description="compensate the robot's weight")
    friction: float = Field(1.0, ge=0, le=1, description="share of the joints' viscous friction compensated")
    damping_nms_rad: float = Field(0.0, ge=0, description="viscous damping kept [N·m·s/rad] (0: none; some for a "
                                                           "person who would move it faster than is safe)")


def joint_damping(model) -> np.ndarray:
    """The viscous damping of each of the robot's joints in its MJCF [N·m·s/rad]."""
    spec = mujoco.MjSpec.from_string(model.mjcf)
    return np.array([float(spec.joint(name).damping[0]) for name in model.joint_names])


class Transparent(Controller):
    """τ = g(q) + (c·b − d)·q̇: the robot carries itself and cancels its joints' friction; the person moves it."""

    def __init__(self, config: TransparentConfig, context: Context):
        self.gravity = context.robot.gravity_torque if config.gravity else None
        self.friction = config.friction * joint_damping(context.robot.model) - config.damping_nms_rad

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        tau = self.friction * qd
        if self.gravity is not None:
            tau += self.gravity(q)
        return tau


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("transparent", config=TransparentConfig, factory=Transparent)
