"""The robot plugin kind: a robot's :class:`~rehabkit.models.robot_model.RobotModel` and its kinematics (closed-form
where the plugin has them, else Pinocchio's and the generic IK)."""

from __future__ import annotations

from abc import ABC
from typing import Any, ClassVar, Literal

import numpy as np

from rehabkit.models.robot_model import RobotModel


class IKUnavailableError(NotImplementedError):
    """The robot has no inverse kinematics for Cartesian targets."""


class Robot(ABC):
    """A robot plugin: its :class:`RobotModel` plus optional closed-form kinematics.

    ``ik_kind`` says what :meth:`ik` matches: a full ``pose``, or the ``position``
    alone (robots with three DoF, whose orientation follows).
    """

    model: RobotModel
    ik_kind: ClassVar[Literal["pose", "position"]] = "pose"
    _pin_data: Any = None  # made on first use (Pinocchio's workspace for the default kinematics)
    _numeric_ik: Any = None  # made on first use (the generic IK)

    def fk(self, q: np.ndarray) -> np.ndarray:
        """End-effector pose (4x4) in the robot base frame. Default: Pinocchio."""
        return self.model.ee_pose(np.asarray(q, dtype=float), self._data())

    def fk_batch(self, qs: np.ndarray) -> np.ndarray:
        """End-effector poses (N, 4, 4) for many configurations. Default: Pinocchio's model, vectorised over the
        batch; a robot with kinematics of its own (an overridden :meth:`fk`) overrides this too, vectorised."""
        if type(self).fk is Robot.fk:
            return self.model.batch_fk(qs)
        return np.array([self.fk(q) for q in np.atleast_2d(qs)])

    def ee_world(self, qs: np.ndarray) -> np.ndarray:
        """End-effector positions (N, 3) in the world for many configurations."""
        base = self.model.base_pose
        return self.fk_batch(qs)[:, :3, 3] @ base[:3, :3].T + base[:3, 3]

    def body_poses(self, body: str, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) and rotations (N, 3, 3) of a body (or site) of the robot's model in the base frame for
        configurations ``qs``. Default: Pinocchio's frames (every serial robot's bodies); a robot whose model
        cannot say (a parallel mechanism's closed loops) overrides it."""
        import pinocchio as pin

        m, data = self.model.pin_model, self._data()
        fid = self._frame_id(body)
        qs = np.atleast_2d(np.asarray(qs, float))
        pos, rot = np.empty((len(qs), 3)), np.empty((len(qs), 3, 3))
        for i, q in enumerate(qs):
            pin.framesForwardKinematics(m, data, q)
            pos[i], rot[i] = data.oMf[fid].translation, data.oMf[fid].rotation
        return pos, rot

    def jacobian(self, q: np.ndarray, frame: str | None = None) -> np.ndarray:
        """The 6×dof Jacobian of a body or site (default: the end effector) at ``q``: its linear velocity (rows
        0–2, of the frame's origin) and angular velocity (rows 3–5), both in the base frame's axes. Default:
        Pinocchio (``LOCAL_WORLD_ALIGNED``)."""
        import pinocchio as pin

        fid = self.model.ee_frame_id if frame is None else self._frame_id(frame)
        return pin.computeFrameJacobian(self.model.pin_model, self._data(), np.asarray(q, float), fid,
                                        pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)  # (a one-joint robot's: a column)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """The joint-space inertia matrix M(q) (dof×dof, symmetric). Default: Pinocchio's CRBA."""
        import pinocchio as pin

        M = pin.crba(self.model.pin_model, self._data(), np.asarray(q, float))
        return np.triu(M) + np.triu(M, 1).T  # (CRBA fills the upper triangle)

    def _frame_id(self, name: str) -> int:
        m = self.model.pin_model
        if not m.existFrame(name):
            from rehabkit.core.kinds.names import suggest

            frames = sorted({f.name for f in m.frames if f.name != "universe"})
            raise ValueError(f"robot '{self.model.name}' has no body or site '{name}'{suggest(name, frames)}")
        return m.getFrameId(name)

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Joint torques moving the robot at ``q``, ``qd``, ``qdd``: its rigid bodies and rotors (Pinocchio's RNEA,
        with the ``armature`` the file declares) and what its joints lose (the declared damping and Coulomb
        friction, :attr:`RobotModel.dissipation`). Default: Pinocchio."""
        import pinocchio as pin

        q, qd = np.asarray(q, float), np.asarray(qd, float)
        return pin.rnea(self.model.pin_model, self._data(), q, qd, np.asarray(qdd, float)) \
            + self.model.dissipation.torque(qd)

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Joint torques holding the robot still against gravity at ``q``. Default: Pinocchio's RNEA at rest
        (``computeGeneralizedGravity``: its velocity and acceleration terms left out, not added as zeros)."""
        import pinocchio as pin

        return pin.computeGeneralizedGravity(self.model.pin_model, self._data(), np.asarray(q, float))

    def gravity_torques(self, qs: np.ndarray) -> np.ndarray:
        """:meth:`gravity_torque` for the rows of ``qs`` (N, dof). Default: Pinocchio's RNEA over the batch (in
        C++); a robot with a gravity model of its own (an overridden :meth:`gravity_torque`) overrides this too."""
        qs = np.atleast_2d(np.asarray(qs, float))
        if type(self).gravity_torque is not Robot.gravity_torque:
            return np.array([self.gravity_torque(q) for q in qs]).reshape(len(qs), -1)
        import pinocchio as pin

        m, zero = self.model.pin_model, np.zeros((self.model.dof, len(qs)))
        return pin.rneaInParallel(1, pin.ModelPool(m, 1), np.ascontiguousarray(qs.T), zero, zero).T

    def _data(self):
        if self._pin_data is None:
            self._pin_data = self.model.new_pin_data()
        return self._pin_data

    def ik(self, pose: np.ndarray, reference: np.ndarray | None = None) -> list[np.ndarray]:
        """Every joint solution reaching ``pose`` (4x4, base frame), nearest ``reference`` first. Default: the
        numeric IK of :attr:`numeric_ik`; robots with an analytic IK override this (and set :attr:`ik_kind`).

        ``reference`` is the current configuration, when there is one: joints the IK does not
        solve for (a lift, a gripper) keep their values from it.
        """
        return self.numeric_ik.solve(pose, reference)

    def solve_ik(self, pose: np.ndarray, reference: np.ndarray | None = None, free: str = "") -> list[np.ndarray]:
        """Solutions for a pose whose tool rotation is free about the axes in ``free`` (``"xyz"``: position only):
        the robot's own :meth:`ik` where it answers that question, else the numeric IK."""
        own = type(self).ik is not Robot.ik
        if own and (self.ik_kind == "position" or not free):
            return self.ik(pose, reference)
        return self.numeric_ik.solve(pose, reference, free)

    @property
    def ik_closest_m(self) -> float:
        """How near the generic IK's last unsuccessful solve came to its target [m] (NaN before it has run)."""
        return self._numeric_ik.closest_m if self._numeric_ik is not None else float("nan")

    @property
    def numeric_ik(self):
        """The generic IK from the robot's Pinocchio model (:class:`rehabkit.models.ik.NumericIK`); it reads
        the joint limits in force (a patient's narrowed ranges) on each solve."""
        if self._numeric_ik is None:
            from rehabkit.models.ik import NumericIK

            try:
                self._numeric_ik = NumericIK(self.model)
            except Exception as exc:  # Pinocchio can't load closed kinematic loops, for one
                raise IKUnavailableError(f"robot '{self.model.name}' has no inverse kinematics: its model does "
                                         f"not load in Pinocchio ({exc})") from exc
        return self._numeric_ik

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.model!r})"
