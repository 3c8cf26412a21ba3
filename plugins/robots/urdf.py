"""Robots from a URDF file."""

from __future__ import annotations

import pinocchio as pin

from rehabkit import hookimpl
from rehabkit.models.mjcf_import import ModelFileConfig, robot_from_file
from rehabkit.plugin import Context, Robot


class UrdfRobot(Robot):
    """Robot from a URDF file (MuJoCo imports it; speed and effort limits read by Pinocchio)."""

    def __init__(self, config: ModelFileConfig, context: Context):
        path = context.resolve(config.file)
        velocity, effort = {}, {}
        if path.exists():
            urdf = pin.buildModelFromUrdf(str(path))  # MuJoCo's importer keeps ranges, not speeds
            for jid in range(1, urdf.njoints):
                idx = urdf.joints[jid].idx_v
                velocity[urdf.names[jid]] = float(urdf.velocityLimit[idx])
                effort[urdf.names[jid]] = float(urdf.effortLimit[idx])
        self.model = robot_from_file(path, config, velocity, effort)


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("urdf", config=ModelFileConfig, factory=UrdfRobot)
