"""Robots written as a DH table in the scenario itself (no code, no model file)."""

from __future__ import annotations

from rehabkit.kinematics import DHRobotSpec, build_dh_robot
from rehabkit.plugin import Context, Robot, hookimpl


class DHRobot(Robot):
    """Serial robot from a standard or modified DH table, masses and radii (MJCF generated)."""

    def __init__(self, config: DHRobotSpec, context: Context | None = None):
        self.spec = config
        self.model = build_dh_robot(config)


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("dh", config=DHRobotSpec, factory=DHRobot)
