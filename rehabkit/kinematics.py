"""Public helpers for robot plugins: kinematic chains, DH descriptions, the robot model, MJCF building, wearables
and robot description files (MJCF, URDF).

A robot plugin (built-in or third-party) imports these from here; the modules they live in are internal and may
move. Each name loads its own module on first use, so importing this module costs nothing (loading a robot file
imports MuJoCo, building a chain does not).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

if TYPE_CHECKING:
    from rehabkit.models.chain import (
        DHRow,
        KinematicChain,
        inv_se3,
        matrix_to_quat_wxyz,
        mdh_transform,
        rot_x,
        rpy_to_matrix,
        trans,
    )
    from rehabkit.models.dh import DHRobotSpec, DHRowSpec, JointSpec, PoseSpec, build_dh_robot, links_and_limits
    from rehabkit.models.files.mjcf_import import ModelFileConfig, ModelFileError, robot_from_file
    from rehabkit.models.files.ros_package import DescriptionError, prepared, resolve_uri, visual_only
    from rehabkit.models.mjcf_builder import ROBOT_CONAFFINITY, ROBOT_CONTYPE, build_chain_mjcf
    from rehabkit.models.robot_model import JointLimits, RobotModel, SafeStop
    from rehabkit.models.strict import FilePath
    from rehabkit.models.wearable import Strap, Wearable

_FROM = {
    "rehabkit.models.chain": ("DHRow", "KinematicChain", "inv_se3", "matrix_to_quat_wxyz",
                              "mdh_transform", "rot_x", "rpy_to_matrix", "trans"),
    "rehabkit.models.dh": ("DHRobotSpec", "DHRowSpec", "JointSpec", "PoseSpec", "build_dh_robot", "links_and_limits"),
    "rehabkit.models.robot_model": ("JointLimits", "RobotModel", "SafeStop"),
    "rehabkit.models.mjcf_builder": ("ROBOT_CONAFFINITY", "ROBOT_CONTYPE", "build_chain_mjcf"),
    "rehabkit.models.wearable": ("Strap", "Wearable"),
    "rehabkit.models.strict": ("FilePath",),
    "rehabkit.models.files.mjcf_import": ("ModelFileConfig", "ModelFileError", "robot_from_file"),
    "rehabkit.models.files.ros_package": ("DescriptionError", "prepared", "resolve_uri", "visual_only"),
}

__all__ = [
    "DHRow", "KinematicChain", "inv_se3", "matrix_to_quat_wxyz", "mdh_transform", "rot_x", "rpy_to_matrix", "trans",
    "DHRobotSpec", "DHRowSpec", "JointSpec", "PoseSpec", "build_dh_robot", "links_and_limits", "JointLimits",
    "RobotModel", "SafeStop", "ROBOT_CONAFFINITY", "ROBOT_CONTYPE", "build_chain_mjcf", "Strap", "Wearable",
    "FilePath", "ModelFileConfig", "ModelFileError", "robot_from_file", "DescriptionError", "prepared",
    "resolve_uri", "visual_only",
]


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
