"""Robots from a URDF file, or a ROS description package's URDF or xacro."""

from __future__ import annotations

import math

import pinocchio as pin
from pydantic import Field

from rehabkit.kinematics import (
    DescriptionError,
    FilePath,
    ModelFileConfig,
    ModelFileError,
    prepared,
    resolve_uri,
    robot_from_file,
    visual_only,
)
from rehabkit.plugin import Context, Robot, SettingError, hookimpl


class UrdfConfig(ModelFileConfig):
    """A URDF (or ``.xacro``) file, its meshes as a ROS description package refers to them."""

    packages: list[FilePath] = Field([], description="folders of ROS packages its package:// URIs name (besides "
                                     "ROS_PACKAGE_PATH and AMENT_PREFIX_PATH): a package's own folder, or one "
                                     "holding packages")
    xacro_args: dict[str, str] = Field({}, description="a .xacro file's arguments (name: value)")


class UrdfRobot(Robot):
    """Robot from a URDF file (MuJoCo imports it; speed and effort limits read by Pinocchio), the description made
    loadable first: xacro expanded, package:// and file:// URIs resolved, COLLADA meshes converted."""

    def __init__(self, config: UrdfConfig, context: Context):
        packages = [context.resolve(p) for p in config.packages]
        try:  # a path, or a URI as ROS tools take one (package://NAME/urdf/robot.urdf, file://)
            path = (resolve_uri(config.file, context.scenario_dir, packages, what="description") if "://" in config.file
                    else context.resolve(config.file))
        except DescriptionError as exc:
            raise SettingError("file", f"{exc.uri}: {exc.problem}", fix=exc.fix) from None
        if not path.exists():
            raise SettingError("file", f"no such file: {path}")
        try:
            path = prepared(path, packages, config.xacro_args)
        except DescriptionError as exc:
            raise SettingError("file", f"{exc.uri}: {exc.problem}", fix=exc.fix) from None
        if (left := visual_only(path)) is not None and context.note is not None:
            context.note(0.0, left)
        velocity, effort = {}, {}
        urdf = pin.buildModelFromUrdf(str(path))  # MuJoCo's importer keeps ranges, not speeds
        for jid in range(1, urdf.njoints):
            idx = urdf.joints[jid].idx_v
            velocity[urdf.names[jid]] = float(urdf.velocityLimit[idx])
            effort[urdf.names[jid]] = float(urdf.effortLimit[idx])
            _radians(urdf, jid, path)
        try:
            self.model = robot_from_file(path, config, velocity, effort)
        except ModelFileError as exc:
            if exc.setting is None:
                raise
            raise SettingError(exc.setting, exc.problem, fix=exc.fix) from None


def _radians(urdf, jid: int, path) -> None:
    """A revolute joint's limits as URDF has them, in radians: a range of more than two turns each way is degrees
    written where radians go (``lower="-90"``), refused with what they would be."""
    shape = urdf.joints[jid].shortname()
    if not shape.startswith("JointModelR") or shape.startswith("JointModelRUB"):  # (continuous joints: no range)
        return
    at = urdf.joints[jid].idx_q
    lo, hi = float(urdf.lowerPositionLimit[at]), float(urdf.upperPositionLimit[at])
    if max(abs(lo), abs(hi)) > 4 * math.pi:
        raise SettingError("file", f"{path.name}: joint '{urdf.names[jid]}' has limits {lo:g} to {hi:g} rad, "
                                   f"{max(abs(lo), abs(hi)) / (2 * math.pi):.1f} turns: URDF limits are radians — if "
                                   f"those are degrees, write lower=\"{math.radians(lo):.4f}\" upper=\""
                                   f"{math.radians(hi):.4f}\"",
                           data={"joint": urdf.names[jid], "lower": lo, "upper": hi})


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("urdf", config=UrdfConfig, factory=UrdfRobot)
