"""A URDF's joint tree and its kinematics, as ``robot_state_publisher`` reads them: each joint from its parent link
to its child link (its ``<origin>``, then its motion about or along its ``<axis>``), a ``<mimic>`` joint at its
leader's value times its multiplier plus its offset, a fixed joint at its origin alone.

This is what a run's ``/tf`` and ``/tf_static`` are made of (:mod:`rehabkit.ros.tf_tree`): the tree as the file has
it, every link under its own parent.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

MOVING = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class UrdfJoint:
    """A URDF joint: ``parent`` → ``child`` link, of ``type``; ``origin`` (4x4) its pose in the parent link, ``axis``
    (unit) its motion's; ``mimic`` the ``(leader, multiplier, offset)`` it follows, if it does."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    mimic: tuple[str, float, float] | None = None

    @property
    def moving(self) -> bool:
        return self.type in MOVING

    def motion(self, value: float) -> np.ndarray:
        """The child link in the parent link (4x4) at joint ``value`` [rad or m]."""
        m = np.eye(4)
        if self.type == "prismatic":
            m[:3, 3] = self.axis * value
        elif self.type in ("revolute", "continuous"):
            x, y, z = self.axis
            k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
            m[:3, :3] = np.eye(3) + np.sin(value) * k + (1.0 - np.cos(value)) * (k @ k)
        return self.origin @ m


@dataclass(frozen=True)
class UrdfTree:
    """A URDF's links (in the file's order), its joints, and its root link (the one no joint has as its child)."""

    links: list[str]
    joints: list[UrdfJoint]
    root: str

    def joint_values(self, values: Mapping[str, float]) -> dict[str, float]:
        """Every moving joint's value from ``values`` (by name), a mimic joint's from its leader's; a joint of
        neither kind is missing from the answer."""
        out = {j.name: float(values[j.name]) for j in self.joints if j.moving and j.name in values}
        for j in self.joints:
            if j.mimic is not None and j.mimic[0] in out and j.name not in values:
                leader, multiplier, offset = j.mimic
                out[j.name] = multiplier * out[leader] + offset
        return out


def _floats(text: str | None, n: int, default: float) -> np.ndarray:
    if text is None:
        return np.full(n, default)
    values = [float(v) for v in text.split()]
    if len(values) != n:
        raise ValueError(f"'{text}' has {len(values)} numbers, not {n}")
    return np.array(values)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    """URDF's roll-pitch-yaw: about the fixed x, then y, then z axis (Rz·Ry·Rx)."""
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _joint(el: ET.Element) -> UrdfJoint:
    name = el.get("name", "")
    origin, m = el.find("origin"), np.eye(4)
    if origin is not None:
        m[:3, :3] = _rpy(*_floats(origin.get("rpy"), 3, 0.0))
        m[:3, 3] = _floats(origin.get("xyz"), 3, 0.0)
    axis_el = el.find("axis")
    given = axis_el.get("xyz") if axis_el is not None else None
    axis = _floats(given, 3, 0.0) if given else np.array([1.0, 0.0, 0.0])  # (URDF's default axis: x)
    norm = float(np.linalg.norm(axis))
    mimic_el = el.find("mimic")
    mimic = None if mimic_el is None else (mimic_el.get("joint", ""), float(mimic_el.get("multiplier", 1.0)),
                                           float(mimic_el.get("offset", 0.0)))
    parent, child = el.find("parent"), el.find("child")
    return UrdfJoint(name, el.get("type", "fixed"), "" if parent is None else parent.get("link", ""),
                     "" if child is None else child.get("link", ""), m, axis / norm if norm > 0 else axis, mimic)


def parse_urdf(text: str) -> UrdfTree:
    """The joint tree of URDF ``text`` (the ``<robot>``'s own ``<link>`` and ``<joint>`` elements: a
    ``<transmission>``'s or ``<ros2_control>``'s joints are not joints of the tree).

    Raises:
        ValueError: not a URDF, or its links do not make one tree (no root, or more than one).
    """
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"not XML: {exc}") from None
    if robot.tag != "robot":
        raise ValueError(f"not a URDF: its root element is <{robot.tag}>, not <robot>")
    links = [el.get("name", "") for el in robot.findall("link")]
    try:
        joints = [_joint(el) for el in robot.findall("joint")]
    except ValueError as exc:
        raise ValueError(f"a joint's numbers: {exc}") from None
    children = {j.child for j in joints}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise ValueError(f"its links make {'no tree' if not roots else 'more than one tree'} (roots: {roots})")
    return UrdfTree(links, joints, roots[0])
