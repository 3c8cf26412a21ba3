"""Velocity-level tasks and constraints of a whole-body stack, from Pinocchio kinematics.

A task gives rows ``A v = b`` on the generalised velocity ``v`` (floating base twist,
then the joints): ``A`` its Jacobian, ``b`` a feed-forward velocity plus a gain times
the error, so errors do not accumulate (Mohammadi et al., eqs. 13–16). Constraints are
the paper's inequalities: joint position limits as a velocity damper with gain μ,
joint velocity limits, CoM height bounds, and the CoM ground projection kept inside
the support polygon (also as a damper).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
import pinocchio as pin
from pydantic import Field
from scipy.spatial import ConvexHull

from rehabkit.core.kinds.interfaces import StrictModel
from rehabkit.core.kinds.names import suggest
from rehabkit.wholebody.stack import Inequalities

AXIS = {"x": 0, "y": 1, "z": 2}
FREE = 1e9  # bound of an unconstrained velocity (the floating base's)


class FrameTaskSpec(StrictModel):
    """A frame's pose (or position): held where it starts, or following the runner's Cartesian reference."""

    type: Literal["frame"]
    frame: str
    reference: Literal["hold", "runner"] = Field("hold", description="'runner': the plan's position reference")
    position_only: bool = False
    gain: float = Field(10.0, ge=0, description="λ for the position error [1/s]")
    rotation_gain: float = Field(10.0, ge=0, description="λ for the orientation error [1/s]")
    weight: float = Field(1.0, gt=0, description="soft priority within its level (ψ)")


class OrientationTaskSpec(StrictModel):
    """A frame's orientation about chosen world axes, held as it starts (quaternion error)."""

    type: Literal["orientation"]
    frame: str
    axes: list[Literal["x", "y", "z"]] = Field(["x", "y"], min_length=1, description="e.g. roll and pitch only")
    gain: float = Field(10.0, ge=0)
    weight: float = Field(1.0, gt=0)


class PostureTaskSpec(StrictModel):
    """Joint values: ``target_deg`` (default: where they start)."""

    type: Literal["posture"]
    joints: list[str] | None = Field(None, description="default: every joint")
    exclude: list[str] = Field([], description="joints left out (e.g. the throwing arm, in a whole-body posture)")
    target_deg: list[float] | None = None
    gain: float = Field(2.0, ge=0)
    weight: float = Field(1.0, gt=0)


class ComTaskSpec(StrictModel):
    """Centre of mass held where it starts along chosen axes."""

    type: Literal["com"]
    axes: list[Literal["x", "y", "z"]] = ["x", "y"]
    gain: float = Field(5.0, ge=0)
    weight: float = Field(1.0, gt=0)


TaskSpec = Annotated[FrameTaskSpec | OrientationTaskSpec | PostureTaskSpec | ComTaskSpec, Field(discriminator="type")]


class ConstraintSpec(StrictModel):
    """Inequalities applied on every level."""

    joint_damper_mu: float = Field(5.0, gt=0, description="μ of the joint-limit velocity damper [1/s]")
    velocity_fraction: float = Field(1.0, gt=0, le=1, description="share of each joint's speed limit allowed")
    com_height_m: tuple[float, float] | None = Field(None, description="CoM height bounds (world z) [m]")
    support_frames: list[str] = Field([], description="frames whose ground projections span the support polygon")
    support_margin_m: float = Field(0.02, ge=0, description="CoM kept this far inside the polygon edges")
    com_gain: float = Field(5.0, gt=0, description="damper gain of the CoM constraints [1/s]")


class KinematicState:
    """One cycle's kinematics of a floating-base model at configuration ``q`` (Pinocchio)."""

    def __init__(self, model: pin.Model):
        self.model, self.data = model, model.createData()
        self.q = pin.neutral(model)
        # views into ``data``, which every update rewrites in place: Pinocchio's accessors wrap new ones on every call
        self.com, self.com_jacobian = self.data.com[0], self.data.Jcom
        self._poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def update(self, q: np.ndarray) -> None:
        self.q = q
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        pin.jacobianCenterOfMass(self.model, self.data, True)  # into com, com_jacobian: from the kinematics just done

    def frame_id(self, name: str) -> int:
        if not self.model.existFrame(name):
            raise ValueError(f"no frame '{name}' in the model{suggest(name, {f.name for f in self.model.frames})}")
        return self.model.getFrameId(name)

    def placement(self, fid: int) -> pin.SE3:
        return self.data.oMf[fid]

    def pose(self, fid: int) -> tuple[np.ndarray, np.ndarray]:
        """A frame's rotation and position, as views that every update rewrites."""
        views = self._poses.get(fid)
        if views is None:
            oMf = self.data.oMf[fid]
            views = self._poses[fid] = (oMf.rotation, oMf.translation)
        return views

    def jacobian(self, fid: int) -> np.ndarray:
        return pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)


def orientation_error(current: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """Quaternion error (Yuan; the paper's eq. 15), world axes: ``current`` and ``desired`` rotation matrices.

    The error η ε_d − η_d ε − ε_d × ε is the vector part of q_d ⊗ q⁻¹, the quaternion of R_d Rᵀ, taken here
    with its scalar part positive (the shorter way round, so ω = λ·e converges) straight from that matrix:
    building two quaternions through Pinocchio cost ~10 us a call.
    """
    return np.array(_orientation_error(current, desired))


def _orientation_error(current: np.ndarray, desired: np.ndarray) -> tuple[float, float, float]:
    (a, b, c), (d, e, f), (g, h, i) = (desired @ current.T).tolist()  # floats: 9 indexings cost more
    w2 = 2.0 * math.sqrt(max(1.0 + a + e + i, 1e-12))  # 4η
    return (h - f) / w2, (c - g) / w2, (d - b) / w2


class Task:
    """A configured task bound to a model: ``rows(state, ref) -> (A, b)``."""

    def __init__(self, spec, state: KinematicState, joint_names: list[str]):
        self.spec = spec
        self.follows_runner = spec.type == "frame" and spec.reference == "runner"
        nv = state.model.nv
        if spec.type in ("frame", "orientation"):
            self.fid = state.frame_id(spec.frame)
            self.start = state.placement(self.fid).copy()
            self.start_rot = self.start.rotation.copy()
            self.start_p = self.start.translation.copy()
        if spec.type == "orientation":
            self.axes = [AXIS[a] for a in spec.axes]
            self._rows = 3 + np.array(self.axes)  # of the frame's Jacobian
            self._wg = spec.weight * spec.gain
        if spec.type == "posture":
            unknown = [n for n in (spec.joints or []) + spec.exclude if n not in joint_names]
            names = [n for n in (spec.joints or joint_names) if n not in spec.exclude]
            if unknown:
                raise ValueError(f"posture task: unknown joint(s) {unknown}")
            self.idx = np.array([6 + joint_names.index(n) for n in names])
            self.qidx = self.idx + 1  # q has the quaternion's extra entry
            if spec.target_deg is not None and len(spec.target_deg) != len(names):
                raise ValueError(f"posture task: {len(spec.target_deg)} targets for {len(names)} joints")
            self.target = np.radians(spec.target_deg) if spec.target_deg is not None else state.q[self.qidx].copy()
            self.A = np.zeros((len(names), nv))
            self.A[np.arange(len(names)), self.idx] = spec.weight  # constant: weighted once
            self._wg = spec.weight * spec.gain
        if spec.type == "com":
            self.axes = [AXIS[a] for a in spec.axes]
            self.start_com = state.com.copy()

    def rows(self, st: KinematicState, ref: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
        s = self.spec
        if s.type == "frame":
            now = st.placement(self.fid)
            J = st.jacobian(self.fid)
            goal_p, ff = (self.start_p, 0.0) if ref is None else ref
            linear = ff + s.gain * (goal_p - now.translation)
            if s.position_only:
                return (J[:3], linear) if s.weight == 1.0 else (s.weight * J[:3], s.weight * linear)
            b = np.concatenate([linear, s.rotation_gain * orientation_error(now.rotation, self.start_rot)])
            return (J, b) if s.weight == 1.0 else (s.weight * J, s.weight * b)
        if s.type == "orientation":
            J = st.jacobian(self.fid)[3:][self.axes]
            err = orientation_error(st.placement(self.fid).rotation, self.start_rot)[self.axes]
            return s.weight * J, s.weight * s.gain * err
        if s.type == "posture":
            return self.A, (s.weight * s.gain) * (self.target - st.q[self.qidx])
        J = st.com_jacobian[self.axes]
        return s.weight * J, s.weight * s.gain * (self.start_com[self.axes] - st.com[self.axes])


    def fill(self, st: KinematicState, ref: tuple[np.ndarray, np.ndarray] | None, A: np.ndarray,
             b: np.ndarray) -> None:
        """:meth:`rows` written into ``A`` and ``b`` (views of the stack's rows: no arrays made per cycle). A
        posture task's ``A`` is constant: written once by the caller, only ``b`` here."""
        s = self.spec
        if s.type == "posture":
            np.subtract(self.target, st.q[self.qidx], out=b)
            b *= self._wg
            return
        if s.type == "frame":
            rot, pos = st.pose(self.fid)
            J = pin.getFrameJacobian(st.model, st.data, self.fid, pin.LOCAL_WORLD_ALIGNED)
            linear = b[:3]
            np.subtract(self.start_p if ref is None else ref[0], pos, out=linear)
            linear *= s.gain
            if ref is not None:
                linear += ref[1]
            if s.position_only:
                A[:] = J[:3]
            else:
                A[:] = J
                x, y, z = _orientation_error(rot, self.start_rot)
                g = s.rotation_gain
                b[3], b[4], b[5] = g * x, g * y, g * z
            if s.weight != 1.0:
                A *= s.weight
                b *= s.weight
            return
        if s.type == "orientation":
            rot, _ = st.pose(self.fid)
            J = pin.getFrameJacobian(st.model, st.data, self.fid, pin.LOCAL_WORLD_ALIGNED)
            np.multiply(J[self._rows], s.weight, out=A)
            err = _orientation_error(rot, self.start_rot)
            for k, axis in enumerate(self.axes):
                b[k] = err[axis] * self._wg
            return
        A[:], b[:] = self.rows(st, ref)


class Constraints:
    """The stack's inequalities for a model with joint limits (joint order after the 6 base velocities)."""

    def __init__(self, spec: ConstraintSpec, state: KinematicState, lower, upper, velocity):
        self.spec = spec
        self.lower, self.upper = np.asarray(lower), np.asarray(upper)
        self.vmax = np.asarray(velocity) * spec.velocity_fraction
        self.polygon = None
        if spec.support_frames:
            pts = np.array([state.placement(state.frame_id(f)).translation[:2] for f in spec.support_frames])
            hull = ConvexHull(pts)
            # outward normals n and offsets d of the edges: n·p ≤ d inside; shrunk by the margin
            self.polygon = (hull.equations[:, :2], -hull.equations[:, 2] - spec.support_margin_m)
            self.hull_points = pts[hull.vertices]
        self.rows = (2 if spec.com_height_m is not None else 0) + (0 if self.polygon is None else len(self.polygon[1]))
        nv = state.model.nv
        self._ineq = Inequalities(np.empty((self.rows, nv)), np.empty(self.rows), np.full(nv, -FREE), np.full(nv, FREE))
        self._joint_lb, self._joint_ub, self._neg_vmax = self._ineq.lb[6:], self._ineq.ub[6:], -self.vmax

    def build(self, st: KinematicState) -> Inequalities:
        """This cycle's inequalities, in arrays that the next call rewrites (a cycle's allocations cost more than
        its arithmetic)."""
        s = self.spec
        qj = st.q[7:]
        lb, ub = self._joint_lb, self._joint_ub
        np.subtract(self.lower, qj, out=lb)
        lb *= s.joint_damper_mu
        np.maximum(self._neg_vmax, lb, out=lb)
        np.subtract(self.upper, qj, out=ub)
        ub *= s.joint_damper_mu
        np.minimum(self.vmax, ub, out=ub)
        np.maximum(ub, lb, out=ub)  # never empty
        G, h = self._ineq.G, self._ineq.h
        k = 0
        if s.com_height_m is not None:
            G[0] = st.com_jacobian[2]
            np.negative(st.com_jacobian[2], out=G[1])
            z = st.com[2]
            h[0], h[1] = s.com_gain * (s.com_height_m[1] - z), -s.com_gain * (s.com_height_m[0] - z)
            k = 2
        if self.polygon is not None:
            normals, offsets = self.polygon
            np.matmul(normals, st.com_jacobian[:2], out=G[k:])
            hk = h[k:]
            np.subtract(offsets, normals @ st.com[:2], out=hk)
            hk *= s.com_gain
        return self._ineq

    def com_margin(self, com_xy: np.ndarray) -> float:
        """Distance of a point inside the (unshrunk) support polygon to its nearest edge (negative outside)."""
        normals, offsets = self.polygon
        return float(np.min(offsets + self.spec.support_margin_m - normals @ com_xy))
