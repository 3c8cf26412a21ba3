"""Inverse kinematics for any robot Pinocchio can load: pink's differential IK, iterated to convergence from
several starts.

A target is a pose of the end-effector frame in the robot base frame, with some rotation axes of the tool left
free: ``free=""`` asks for the whole pose, ``"z"`` for the tool's z axis to point as the pose's does (turning
about it is free), ``"xyz"`` for the position alone. Each start descends by pink's QP (joint ranges as
constraints); a start that stalls or runs out of iterations is dropped. Robots with an analytic IK keep it
(:meth:`rehabkit.core.kinds.interfaces.Robot.solve_ik` chooses).
"""

from __future__ import annotations

import numpy as np

from rehabkit.models.robot_model import JointLimits, RobotModel

FREE_AXES = ("", "x", "y", "z", "xy", "xz", "yz", "xyz")


class NumericIK:
    """Joint solutions reaching a (partial) pose, by pink (Pinocchio + qpsolvers) from several starts.

    Attributes:
        starts: Starts per solve: the reference posture, then uniform draws within the joint ranges (up to three
            times as many while none has converged).
        max_iter: Gauss–Newton steps per start.
        tol_m: Position error accepted [m].
        tol_rad: Error accepted about each constrained rotation axis [rad].
        closest_m: After a solve that found nothing, how near the best start came [m] (for the error message).
    """

    def __init__(self, model: RobotModel, *, starts: int = 8, max_iter: int = 60, tol_m: float = 1e-5,
                 tol_rad: float = 1e-4, seed: int = 0):
        import pinocchio as pin

        self.robot = model
        self.model = pin.Model(model.pin_model)  # a copy: its ranges are set from the limits in force
        self.data = self.model.createData()
        self.frame = model.pin_model.frames[model.ee_frame_id].name  # (a body named as the end effector: its frame)
        self.starts, self.max_iter, self.tol_m, self.tol_rad, self.seed = starts, max_iter, tol_m, tol_rad, seed
        self.closest_m = float("nan")

    def solve(self, pose: np.ndarray, reference: np.ndarray | None = None, free: str = "",
              limits: JointLimits | None = None, first: bool = False) -> list[np.ndarray]:
        """Distinct solutions for ``pose`` (4x4, base frame), nearest ``reference`` first (default: mid-range);
        with ``first``, the first one found (from the reference when it converges there: the posture's own).

        Starts are drawn from a generator seeded afresh on each call, so the same question gets the same answer.
        """
        lim = self._set_limits(limits)
        ref = 0.5 * (lim.lower + lim.upper) if reference is None else np.clip(reference, lim.lower, lim.upper)
        rng = np.random.default_rng(self.seed)
        found: list[np.ndarray] = []
        self.closest_m = np.inf
        for k in range(self.starts * 3):
            if k >= self.starts and found:  # more starts only while nothing is found (a hard target, or none)
                break
            q0 = ref if k == 0 else rng.uniform(lim.lower, lim.upper)
            q = self._descend(pose, q0, free)
            if q is not None and all(np.abs(q - f).max() > 1e-3 for f in found):
                found.append(q)
                if first:
                    break
        found.sort(key=lambda q: float(np.linalg.norm(q - ref)))
        return found

    def track(self, pose: np.ndarray, q0: np.ndarray, free: str = "", limits: JointLimits | None = None
              ) -> np.ndarray | None:
        """One descent from ``q0`` (a path's previous point): the solution continuing that posture, or ``None``."""
        lim = self._set_limits(limits)
        self.closest_m = np.inf
        return self._descend(pose, np.clip(q0, lim.lower, lim.upper), free)

    def _set_limits(self, limits: JointLimits | None) -> JointLimits:
        lim = limits or self.robot.limits
        self.model.lowerPositionLimit = np.asarray(lim.lower, float)
        self.model.upperPositionLimit = np.asarray(lim.upper, float)
        return lim

    def _descend(self, pose: np.ndarray, q0: np.ndarray, free: str) -> np.ndarray | None:
        import pink
        import pinocchio as pin
        from pink.limits import ConfigurationLimit
        from pink.tasks import FrameTask

        if free not in FREE_AXES:
            raise ValueError(f"free axes {free!r}: expected one of {FREE_AXES}")
        weight = np.array([0.0 if axis in free else 1.0 for axis in "xyz"])
        task = FrameTask(self.frame, position_cost=1.0, orientation_cost=weight)
        task.set_target(pin.SE3(np.asarray(pose, float)))
        conf = pink.Configuration(self.model, self.data, np.array(q0, float))
        limits = [ConfigurationLimit(self.model, 0.5)]  # half the way to a range's end per step: no overshoot
        position_only = free == "xyz"
        goal = np.asarray(pose, float)[:3, 3]
        for _ in range(self.max_iter):
            if position_only:  # the target turned as the tool is: pink's 6-D error (the log of the relative pose)
                # mixes rotation into its position part, and breaks where the tool is turned half a turn from the
                # target's axes (a SCARA's tool pointing down at an identity-oriented point target)
                task.set_target(pin.SE3(conf.get_transform_frame_to_world(self.frame).rotation, goal))
            err = task.compute_error(conf)
            pos, rot = float(np.linalg.norm(err[:3])), float(np.abs(err[3:] * weight).max())
            self.closest_m = min(self.closest_m, pos)
            if pos < self.tol_m and rot < self.tol_rad:
                return conf.q.copy()
            try:
                v = pink.solve_ik(conf, [task], 1.0, solver="daqp", damping=1e-6, limits=limits, safety_break=False)
            except pink.exceptions.NoSolutionFound:
                return None
            if float(np.abs(v).max()) < 1e-9:  # stalled at a range's end or a singularity short of the target
                return None
            conf.update(np.clip(conf.integrate(v, 1.0), self.model.lowerPositionLimit, self.model.upperPositionLimit))
        return None
