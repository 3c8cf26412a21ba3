"""Serial kinematic chains from Denavit-Hartenberg tables.

A chain is stored as fixed transforms interleaved with joint motions about the
local z axis: ``F0 · J1(q1) · F1 · J2(q2) · … · Jn(qn) · Fn``. Both DH
conventions reduce to this form, and so does the same mechanism seen from its
other end (:meth:`KinematicChain.reversed`), which is what the reverse
coordinate method of inverse kinematics relies on.

This module is the reference maths for model *generation* and for tests; at run
time kinematics and dynamics go through Pinocchio.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

JointType = Literal["revolute", "prismatic"]


def rot_x(a: float) -> np.ndarray:
    """Homogeneous rotation about x by ``a`` [rad]."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_z(a: float) -> np.ndarray:
    """Homogeneous rotation about z by ``a`` [rad]."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """Homogeneous translation [m]."""
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def inv_se3(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, without a general matrix inverse."""
    out = np.eye(4)
    r = t[:3, :3].T
    out[:3, :3] = r
    out[:3, 3] = -r @ t[:3, 3]
    return out


def rpy_to_matrix(rpy: Sequence[float]) -> np.ndarray:
    """3x3 rotation from roll, pitch, yaw [rad] (fixed axes x, then y, then z)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def pose(position: Sequence[float] = (0, 0, 0), rpy: Sequence[float] = (0, 0, 0)) -> np.ndarray:
    """4x4 transform from a position [m] and roll-pitch-yaw [rad]."""
    t = np.eye(4)
    t[:3, :3] = rpy_to_matrix(rpy)
    t[:3, 3] = position
    return t


def matrix_to_quat_wxyz(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a 3x3 rotation matrix (Shepperd's method)."""
    tr = np.trace(r)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q) * (1 if q[0] >= 0 else -1)


@dataclass(frozen=True)
class DHRow:
    """One row of a DH table. Lengths in [m], angles in [rad].

    For the modified (Craig) convention ``a`` and ``alpha`` are a_{i-1} and
    alpha_{i-1}, the parameters of the link *before* joint i.
    """

    a: float
    alpha: float
    d: float
    theta_offset: float = 0.0
    joint: JointType = "revolute"


def mdh_transform(row: DHRow, q: float) -> np.ndarray:
    """Modified DH: ``Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``."""
    theta, d = row.theta_offset, row.d
    if row.joint == "revolute":
        theta += q
    else:
        d += q
    return rot_x(row.alpha) @ trans(x=row.a) @ rot_z(theta) @ trans(z=d)


def sdh_transform(row: DHRow, q: float) -> np.ndarray:
    """Standard DH: ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``."""
    theta, d = row.theta_offset, row.d
    if row.joint == "revolute":
        theta += q
    else:
        d += q
    return rot_z(theta) @ trans(z=d) @ trans(x=row.a) @ rot_x(row.alpha)


@dataclass(frozen=True)
class KinematicChain:
    """``F0 · J1(q1) · F1 · … · Jn(qn) · Fn`` with each Ji about local z.

    Attributes:
        fixed: n+1 homogeneous transforms.
        joints: n joint types.
    """

    fixed: tuple[np.ndarray, ...]
    joints: tuple[JointType, ...]

    @property
    def dof(self) -> int:
        return len(self.joints)

    @staticmethod
    def _motion(kind: JointType, q: float) -> np.ndarray:
        return rot_z(q) if kind == "revolute" else trans(z=q)

    @classmethod
    def from_dh(cls, rows: Sequence[DHRow], convention: Literal["standard", "modified"]) -> KinematicChain:
        """Split a DH table into fixed parts and joint motions."""
        fixed: list[np.ndarray] = []
        pending = np.eye(4)
        for row in rows:
            if convention == "modified":
                before = rot_x(row.alpha) @ trans(x=row.a)
                after = trans(z=row.d)
            else:
                before = np.eye(4)
                after = trans(z=row.d) @ trans(x=row.a) @ rot_x(row.alpha)
            # the constant part of theta_i sits on the joint axis, before the motion
            fixed.append(pending @ before @ rot_z(row.theta_offset))
            pending = after
        fixed.append(pending)
        return cls(tuple(fixed), tuple(r.joint for r in rows))

    def reversed(self) -> KinematicChain:
        """The same mechanism described from its tip to its base.

        Joint i of the reversed chain is joint n+1-i of this one, with its
        variable negated: ``reversed().fk(-q[::-1]) == inv(fk(q))``.
        """
        return KinematicChain(tuple(inv_se3(f) for f in reversed(self.fixed)), tuple(reversed(self.joints)))

    def frames(self, q: Sequence[float]) -> list[np.ndarray]:
        """Pose of each joint frame (after its motion) and, last, of the tip."""
        t = self.fixed[0].copy()
        out = []
        for kind, qi, f in zip(self.joints, q, self.fixed[1:]):
            t = t @ self._motion(kind, qi)
            out.append(t.copy())
            t = t @ f
        out.append(t)
        return out

    def fk(self, q: Sequence[float]) -> np.ndarray:
        """Tip pose for joint values ``q``."""
        return self.frames(q)[-1]

    def fk_batch(self, q: np.ndarray) -> np.ndarray:
        """Tip poses (N, 4, 4) for many configurations (N, n) at once."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n = len(q)
        # the poses' top three rows held column by column, each column's entries contiguous over the batch:
        # t[column, row, sample]. A joint's motion mixes whole columns (a rotation about z mixes x and y, a slide adds
        # z to the origin); the constant part is one (4, 3) @ (3, 3N) product (its bottom row [0 0 0 1] carries the
        # origin over). ~2x faster than (N, 4, 4) stacks, whose columns are strided
        t = np.empty((4, 3, n))
        t[:] = self.fixed[0][:3].T[:, :, None]
        for i, kind in enumerate(self.joints):
            if kind == "revolute":
                c, s = np.cos(q[:, i]), np.sin(q[:, i])
                x = t[0] * c
                x += s * t[1]
                t[1] *= c
                t[1] -= s * t[0]
                t[0] = x
            else:
                t[3] += q[:, i] * t[2]
            origin = t[3].copy()
            t = (self.fixed[i + 1][:3].T @ t[:3].reshape(3, 3 * n)).reshape(4, 3, n)
            t[3] += origin
        out = np.zeros((n, 4, 4))
        out[:, :3, :] = t.transpose(2, 1, 0)
        out[:, 3, 3] = 1.0
        return out
