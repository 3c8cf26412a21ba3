"""A frame's pose for many configurations at once, from a Pinocchio model, vectorised over the batch.

Pinocchio evaluates one configuration per call; over a whole run (thousands of
samples for the outcome measures, a plan checked every 5 ms) the Python loop
around it dominates. Here the chain from the root to the frame is read from the
model once — each joint's placement in its parent and its motion (a rotation
about, or a translation along, a fixed axis) — and evaluated for all samples
with numpy: one batched 4×4 product per joint. The frame's position Jacobians
come from the same pass: each joint's axis and origin in the root frame.
"""

from __future__ import annotations

import numpy as np

_AXES = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


def _motion_kind(joint) -> tuple[str, np.ndarray] | None:
    """('R' | 'P', unit axis) of a one-DoF joint, or ``None`` for joints not vectorised here."""
    name = joint.shortname()
    if name in ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelPX", "JointModelPY", "JointModelPZ"):
        return name[10], _AXES[name[11]]
    if name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        axis = np.asarray(joint.extract().axis, float).ravel()
        return ("R" if name.startswith("JointModelRevolute") else "P"), axis / np.linalg.norm(axis)
    return None


class BatchFK:
    """``fk(qs) -> (N, 4, 4)``: the pose of frame ``frame_id`` (in the model's root frame) for each row of ``qs``.

    ``vectorised`` is False when the chain has a joint kind not handled here (then each sample goes through
    Pinocchio, as before).
    """

    def __init__(self, model, frame_id: int):
        self.model, self.frame_id = model, frame_id
        frame = model.frames[frame_id]
        chain, j = [], frame.parentJoint
        while j > 0:
            chain.append(j)
            j = model.parents[j]
        self.steps: list[tuple[np.ndarray, str, np.ndarray, int, int]] = []
        self.vectorised = True
        for j in reversed(chain):
            kind = _motion_kind(model.joints[j])
            if kind is None:
                self.vectorised = False
                break
            joint = model.joints[j]
            self.steps.append((model.jointPlacements[j].homogeneous, kind[0], kind[1], joint.idx_q, joint.idx_v))
        self.tip = frame.placement.homogeneous

    def __call__(self, qs: np.ndarray) -> np.ndarray:
        qs = np.atleast_2d(np.asarray(qs, float))
        if not self.vectorised:
            return self._each(qs)
        return self._chain(qs)[0]

    def jacobian(self, qs: np.ndarray) -> np.ndarray:
        """Position Jacobians (N, 3, nv) of the frame, in the root frame's axes (the linear rows of Pinocchio's
        ``LOCAL_WORLD_ALIGNED`` frame Jacobian)."""
        qs = np.atleast_2d(np.asarray(qs, float))
        if not self.vectorised:
            return self._each_jacobian(qs)
        tip, joints = self._chain(qs)
        out = np.zeros((len(qs), 3, self.model.nv))
        for (_, kind, _, _, iv), (origin, axis) in zip(self.steps, joints):
            out[:, :, iv] = np.cross(axis, tip[:, :3, 3] - origin) if kind == "R" else axis
        return out

    def _chain(self, qs: np.ndarray) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
        """The frame's poses (N, 4, 4), and each joint's origin and axis (N, 3) in the root frame."""
        n = len(qs)
        t = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        joints = []
        for placement, kind, axis, iq, _ in self.steps:
            t = t @ placement
            joints.append((t[:, :3, 3], t[:, :3, :3] @ axis))  # a joint's own motion leaves its axis in place
            m = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            v = qs[:, iq]
            if kind == "R":  # Rodrigues: R = I + sin θ K + (1 − cos θ) K²
                k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
                m[:, :3, :3] += np.sin(v)[:, None, None] * k + (1 - np.cos(v))[:, None, None] * (k @ k)
            else:
                m[:, :3, 3] = v[:, None] * axis
            t = t @ m
        return t @ self.tip, joints

    def _each(self, qs: np.ndarray) -> np.ndarray:
        import pinocchio as pin

        data = self.model.createData()
        out = np.empty((len(qs), 4, 4))
        for i, q in enumerate(qs):
            pin.framesForwardKinematics(self.model, data, q)
            out[i] = data.oMf[self.frame_id].homogeneous
        return out

    def _each_jacobian(self, qs: np.ndarray) -> np.ndarray:
        import pinocchio as pin

        data = self.model.createData()
        return np.stack([pin.computeFrameJacobian(self.model, data, q, self.frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
                         for q in qs])
