"""A run's ``/tf`` and ``/tf_static``, as ``robot_state_publisher`` would publish them from ``/robot_description``:
every joint of the description from its parent link to its child link (a fixed joint's once, a moving or mimic
joint's at the log rate, from the run's joint values), and where the scenario put the robot.

The scenario's base placement (``robot.base``) is ``world → <the description's root link>``: ``world`` is the
scene's frame, above the description's own tree, which is published as the file has it. A description whose root
link is itself named ``world`` (xArm's ``world → link_base``) is taken as already in the scene, as Gazebo takes
it: its joints from ``world`` are published with the placement put before them (identity where the scenario
leaves the base where it is). A floating robot's root is ``world → <root link>`` at the log rate.

Frames the bag's messages are given in that the description lacks (an end effector's site) hang, fixed, from the
nearest link above them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from rehabkit.ros.urdf_tree import UrdfTree, parse_urdf

WORLD = "world"  # the scene's frame: the base placement's parent


@dataclass(frozen=True)
class Transform:
    """``child``'s pose in ``parent`` (4x4)."""

    parent: str
    child: str
    matrix: np.ndarray


class TfTree:
    """The transforms of a robot's description (``description``: its URDF text) for a robot model ``robot`` (a
    ``RobotModel``: joint names, base pose, Pinocchio model); ``frames``: other frames the bag uses (e.g. the
    wrench's), published where the description lacks them.

    Attributes:
        base: The frame the bag gives base-frame quantities in (a target, a seen target): the description's root
            link, or ``world`` for a description rooted at ``world``.
        base_to_frame: 4x4 from the robot's base frame (its kinematics') to :attr:`base`.
    """

    def __init__(self, description: str, robot, frames: Iterable[str] = (), floating: bool = False):
        import pinocchio as pin

        self.tree: UrdfTree = parse_urdf(description)
        self.model = model = robot.pin_model
        self.data = model.createData()
        pin.framesForwardKinematics(model, self.data, pin.neutral(model))
        root = self.tree.root
        body = model.existFrame(root) and str(model.frames[model.getFrameId(root)].type).endswith("BODY")
        # (the model's root body is the description's root link; a root named world is the scene, not a body)
        self.root_in_base = self.data.oMf[model.getFrameId(root)].homogeneous.copy() if body else np.eye(4)
        self.placement = np.asarray(robot.base_pose, float)
        self.world_rooted = root == WORLD
        self.floating = floating
        self.base = WORLD if self.world_rooted else root
        self.base_to_frame = self.placement if self.world_rooted else np.linalg.inv(self.root_in_base)
        self.names = list(robot.joint_names)
        self._unknown = [j for j in self.tree.joints if j.moving and j.mimic is None and j.name not in self.names]
        self.extra = self._extra_frames(frames)

    def _extra_frames(self, frames: Iterable[str]) -> list[Transform]:
        """Frames the description lacks, fixed to the nearest link above them (or the base)."""
        model, data, links = self.model, self.data, set(self.tree.links)
        out = []
        for name in dict.fromkeys(frames):
            if not name or name in links or name == WORLD or not model.existFrame(name):
                continue
            fid = p = model.getFrameId(name)
            while p > 0 and model.frames[p].name not in links:
                if str(model.frames[p].type).endswith("JOINT") and model.frames[p].parentJoint > 0 and \
                        not str(model.frames[p].type).endswith("FIXED_JOINT"):
                    p = -1  # (a joint between it and the link above: not fixed to it)
                    break
                p = model.frames[p].parentFrame
            if p < 0:
                continue
            if p > 0:
                out.append(Transform(model.frames[p].name, name, data.oMf[p].actInv(data.oMf[fid]).homogeneous))
            else:
                out.append(Transform(self.base, name, self.base_to_frame @ data.oMf[fid].homogeneous))
        return out

    def _placed(self, joint_parent: str, m: np.ndarray) -> np.ndarray:
        """A joint's transform, the placement before it where the description's root is the scene's world."""
        return self.placement @ m if self.world_rooted and joint_parent == WORLD else m

    def static(self) -> list[Transform]:
        """``/tf_static``: the description's fixed joints, the base placement (a fixed robot's), the extra frames."""
        out = [Transform(j.parent, j.child, self._placed(j.parent, j.origin)) for j in self.tree.joints
               if not j.moving and j.mimic is None]
        if not self.world_rooted and not self.floating:
            out.append(Transform(WORLD, self.tree.root, self.placement @ self.root_in_base))
        return out + self.extra

    def moving(self, q: np.ndarray, root_pose: np.ndarray | None = None) -> list[Transform]:
        """``/tf`` at joint values ``q`` (the robot's joints, in its order): each moving or mimic joint, and a floating
        robot's root at ``root_pose`` (its base's pose in the world, 4x4)."""
        values = self.tree.joint_values(dict(zip(self.names, map(float, q), strict=True)))
        if self._unknown:  # (a joint the model does not move: as the model has it)
            import pinocchio as pin

            pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        out = []
        for j in self.tree.joints:
            if not j.moving and j.mimic is None:
                continue
            if j.name in values:
                m = j.motion(values[j.name])
            elif self.model.existFrame(j.parent) and self.model.existFrame(j.child):
                m = self.data.oMf[self.model.getFrameId(j.parent)].actInv(
                    self.data.oMf[self.model.getFrameId(j.child)]).homogeneous
            else:
                m = j.origin
            out.append(Transform(j.parent, j.child, self._placed(j.parent, m)))
        if self.floating and root_pose is not None:
            out.append(Transform(WORLD, self.tree.root, root_pose @ self.root_in_base))
        return out
