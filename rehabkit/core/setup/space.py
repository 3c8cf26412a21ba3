"""The space a run's reference is in — joint values or hand positions — fixed once at setup.

Everything that differs between a joint-space and a Cartesian planner is said here, once: where the reference
starts, where a reference point puts the hand, how a plan's path is drawn and its waypoints listed, which
trajectories are checked against the joint limits, what the trace records beside the joints and which goal
the tracking metrics measure. The run never asks which space it is in.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rehabkit.core.kinds.capabilities import SceneGeometry
from rehabkit.core.kinds.interfaces import Plan
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.safety.limit_breach import LimitBreach, plan_breach


class JointSpace:
    """References are joint values [rad]; the hand follows by the robot's forward kinematics."""

    name = "joint"

    def __init__(self, setup):
        self.robot, self.controller = setup.robot, setup.controller
        self._revolute = np.asarray(setup.robot.model.revolute, bool)
        # a plan's waypoints in the summary: degrees where every joint turns; with a slide among them, each joint in
        # its own unit under a key that does not say degrees (a SCARA's quill in metres under waypoints_deg misled)
        self.waypoint_key = "waypoints_deg" if self._revolute.all() else "waypoints"

    def waypoint_scale(self, waypoints: np.ndarray) -> np.ndarray:
        """Waypoints in each joint's unit: degrees for a revolute joint, metres for a prismatic one."""
        return np.where(self._revolute, np.degrees(waypoints), waypoints)

    def point(self, q: np.ndarray) -> np.ndarray:
        """The reference point the joint values ``q`` are at (the start's, a tracking error's)."""
        return q

    def points(self, qs: np.ndarray) -> np.ndarray:
        """:meth:`point` of each row."""
        return qs

    def planned(self, trace: Trace) -> np.ndarray:
        """The trace's planned reference."""
        return trace.q_ref

    def hand(self, x: np.ndarray) -> np.ndarray:
        """Where a reference point puts the hand (base frame)."""
        return self.robot.fk(x)[:3, 3]

    def hand_world(self, xs: np.ndarray) -> np.ndarray:
        """Where reference points (rows) put the hand, in the world."""
        return self.robot.ee_world(xs)

    def limit_breach(self, plan: Plan, within: float | None = None) -> LimitBreach | None:
        """The first joint limit of the run a plan breaks (in its first ``within`` seconds, where only they run)."""
        return plan_breach(plan, self.robot.model, within)

    def allocate(self, trace: Trace, ref_q: np.ndarray, ref_qd: np.ndarray) -> None:
        """The trace's reference columns: the planned reference, or the controller's own where it makes one; and,
        beside the plan's, the controller's own joint reference where it exposes one (``q_ctrl``)."""
        if self.controller.reference == "own":  # what it tracked is its own reference; record that
            trace.q_ref, trace.qd_ref = np.zeros_like(ref_q), np.zeros_like(ref_qd)
        else:
            trace.q_ref, trace.qd_ref = ref_q, ref_qd
            trace.q_ctrl = np.full_like(ref_q, np.nan)

    def recorder(self, trace: Trace, backend) -> Callable[[int, np.ndarray], None] | None:
        """What the loop records each step beside the joints: the controller's own joint reference."""
        controller = self.controller
        if controller.reference == "own":
            q_ref = trace.q_ref

            def record(k: int, q: np.ndarray) -> None:
                q_ref[k] = controller.joint_reference
            return record
        q_ctrl = trace.q_ctrl

        def record_own(k: int, q: np.ndarray) -> None:  # (a compliant controller's yield: reported beside the plan's)
            if controller.joint_reference is not None:
                q_ctrl[k] = controller.joint_reference
        return record_own

    def goal(self, goal: np.ndarray) -> np.ndarray | None:
        """The joint goal the final-error metrics measure (none where the controller went its own way)."""
        return None if self.controller.reference == "own" else goal

    def metrics(self, trace: Trace) -> dict[str, float]:
        return {}


class CartesianSpace(JointSpace):
    """References are hand positions [m] in the robot's base frame; a controller maps them to the joints."""

    name = "cartesian"
    waypoint_scale = staticmethod(lambda w: w)

    def __init__(self, setup):
        super().__init__(setup)
        self.waypoint_key = "waypoints_m"  # (hand positions)

    def point(self, q: np.ndarray) -> np.ndarray:
        return self.robot.fk(q)[:3, 3]

    def points(self, qs: np.ndarray) -> np.ndarray:
        return self.robot.fk_batch(qs)[:, :3, 3]

    def planned(self, trace: Trace) -> np.ndarray:
        return trace.x_ref

    def hand(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x, float)

    def hand_world(self, xs: np.ndarray) -> np.ndarray:
        return self.robot.model.to_world(np.asarray(xs)[:, :3])

    def limit_breach(self, plan: Plan, within: float | None = None) -> LimitBreach | None:
        return None  # mapped to the joints by the controller, which the safety layer checks step by step

    def allocate(self, trace: Trace, ref_q: np.ndarray, ref_qd: np.ndarray) -> None:
        # the joint reference is the controller's own (closed-loop IK), where it makes one: NaN where it does not
        n = len(trace.t)
        trace.x, trace.x_ref = np.zeros((n, 3)), ref_q
        trace.q_ref[:] = np.nan

    def recorder(self, trace: Trace, backend) -> Callable[[int, np.ndarray], None]:
        base = self.robot.model.base_pose
        p, R = base[:3, 3], base[:3, :3]
        x, q_ref, controller = trace.x, trace.q_ref, self.controller
        # the hand where the backend tracks it (the simulated or mirrored scene), else by the robot's kinematics
        if isinstance(backend, SceneGeometry):
            def hand_world(q: np.ndarray) -> np.ndarray:
                return backend.ee_position()
        else:
            ee = self.robot.ee_world

            def hand_world(q: np.ndarray) -> np.ndarray:
                return ee(q[None])[0]

        def record(k: int, q: np.ndarray) -> None:
            x[k] = (hand_world(q) - p) @ R
            if controller.joint_reference is not None:
                q_ref[k] = controller.joint_reference
        return record

    def goal(self, goal: np.ndarray) -> np.ndarray | None:
        return None

    def metrics(self, trace: Trace) -> dict[str, float]:
        return cartesian_metrics(trace)


def reference_space(setup) -> JointSpace:
    """The space of the scenario's planner (its controller takes the same: checked at setup)."""
    return CartesianSpace(setup) if setup.planner.space == "cartesian" else JointSpace(setup)


def cartesian_metrics(trace: Trace) -> dict[str, float]:
    """How the end effector followed a Cartesian reference."""
    if trace.x is None or not len(trace.x):
        return {}
    err = np.linalg.norm(trace.x_ref - trace.x, axis=1)
    return {
        "cartesian_tracking_rms_mm": float(np.sqrt(np.mean(err**2)) * 1e3),
        "cartesian_tracking_max_mm": float(err.max() * 1e3),
        "final_position_error_m": float(err[-1]),
    }
