"""Robots from an MJCF file."""

from __future__ import annotations

from rehabkit.kinematics import ModelFileConfig, ModelFileError, robot_from_file
from rehabkit.plugin import Context, Robot, SettingError, hookimpl


class MjcfRobot(Robot):
    """Robot from an MJCF file: joints, ranges and effort from the file, speeds from the scenario."""

    def __init__(self, config: ModelFileConfig, context: Context):
        try:
            self.model = robot_from_file(context.resolve(config.file), config)
        except ModelFileError as exc:
            if exc.setting is None:
                raise
            raise SettingError(exc.setting, exc.problem, fix=exc.fix) from None


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("mjcf", config=ModelFileConfig, factory=MjcfRobot)
