"""A robot plugin in code: a two-link arm moving in a vertical plane, its MJCF written from its settings."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, JointLimits, Robot, RobotModel, StrictModel, hookimpl


class PlanarArmConfig(StrictModel):
    """Link lengths and masses, the joints' limits, where the shoulder is."""

    upper_arm_m: float = Field(0.3, gt=0, description="shoulder to elbow [m]")
    forearm_m: float = Field(0.25, gt=0, description="elbow to hand [m]")
    masses_kg: tuple[float, float] = Field((1.5, 1.0), description="each link's mass [kg]")
    range_deg: float = Field(150.0, gt=0, le=180, description="each joint turns within ±this [deg]")
    velocity_deg_s: float = Field(180.0, gt=0, description="speed limit [deg/s]")
    effort_nm: float = Field(30.0, gt=0, description="torque limit [N·m]")
    shoulder_height_m: float = Field(1.0, gt=0, description="shoulder above the floor [m]")


class PlanarArm(Robot):
    """Two links in the x-z plane, hinged about y; the hand is the forearm's tip."""

    def __init__(self, config: PlanarArmConfig, context: Context | None = None):
        l1, l2 = config.upper_arm_m, config.forearm_m
        m1, m2 = config.masses_kg
        link = '<geom type="capsule" fromto="0 0 0 {l} 0 0" size="0.03" mass="{m}"/>'
        mjcf = f"""<mujoco model="planar-arm"><compiler angle="radian"/><worldbody>
  <body name="shoulder_mount"><geom type="sphere" size="0.05" contype="0" conaffinity="0" mass="0"/>
    <body name="upper_arm"><joint name="shoulder" axis="0 -1 0"/>{link.format(l=l1, m=m1)}
      <body name="forearm" pos="{l1} 0 0"><joint name="elbow" axis="0 -1 0"/>{link.format(l=l2, m=m2)}
        <site name="hand" pos="{l2} 0 0"/></body></body></body>
</worldbody></mujoco>"""
        r, n = np.radians(config.range_deg), 2
        limits = JointLimits(np.full(n, -r), np.full(n, r), np.full(n, np.radians(config.velocity_deg_s)),
                             np.full(n, config.effort_nm))
        base = np.eye(4)
        base[2, 3] = config.shoulder_height_m
        self.model = RobotModel("planar-arm", mjcf, ["shoulder", "elbow"], limits, "hand", base_pose=base)


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("planar-arm", config=PlanarArmConfig, factory=PlanarArm)
