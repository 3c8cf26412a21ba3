"""Deterministic gripper path around obstacles, timed at the ARM's speed (after Stuyt et al.).

The gripper tip goes from where it is to each target along the polyline of
:func:`rehabkit.geometry.box_avoid.plan_path` (over the faces of the scene's static
objects, inflated by a margin for the gripper's size, never under the floor). Each
straight piece is run rest to rest with a minimum-jerk time law whose peak speed is the
ARM's Cartesian limit; the gripper turns from its start orientation to the target's in
proportion to the distance covered (the paper keeps it constant; a stored target has
its own). The closed-form IK turns dense samples into joint values (nearest branch to
the previous sample), and a piece whose joint speeds would pass the limits is slowed.
"""

from __future__ import annotations

import time
from bisect import bisect_right
from typing import Literal

import numpy as np
from pydantic import Field
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from rehabkit.kinematics import rpy_to_matrix
from rehabkit.planning import NoPathError, Solid, make_solid, plan_path
from rehabkit.plugin import (
    Context,
    Metric,
    Plan,
    Planner,
    PlanningError,
    PlanRequest,
    SettingError,
    StrictModel,
    angular_distance,
    hookimpl,
)
from rehabkit.trajectories import PEAK_VELOCITY as PEAK
from rehabkit.trajectories import quintic


class BoxAvoidConfig(StrictModel):
    """Obstacles, margins and speeds."""

    obstacles: list[str] | None = Field(None, description="world objects to avoid (default: every static one)")
    margin: float = Field(0.07, ge=0, description="gripper size: every obstacle is inflated by it [m]")
    clearance: float = Field(0.005, ge=0, description="further gap at which the faces are followed [m]")
    speed_m_s: float = Field(0.09, gt=0, le=0.099, description="peak gripper speed (the ARM's limit is 9.9 cm/s)")
    joint_speed_fraction: float = Field(0.9, gt=0, le=1, description="peak joint speed / joint limit")
    sample_hz: float = Field(50.0, gt=0, description="IK samples per second of motion")
    orientation: Literal["blend", "keep"] = Field("blend", description="turn to each target's orientation, or "
                                                  "keep the start's (position-only targets always keep it)")


class PiecewiseSpline:
    """Joint trajectory made of rest-to-rest cubic splines, one per polyline piece."""

    def __init__(self, pieces: list[CubicSpline], starts: np.ndarray):
        self.pieces, self.starts = pieces, starts
        self.duration = float(starts[-1])
        self._starts, self._knots = starts.tolist(), [p.x.tolist() for p in pieces]  # for bisect

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, float))
        if t.shape == (1,):  # the control loop's one sample a step: three scipy calls cost ~80 µs of the step
            return self._at(min(max(float(t[0]), 0.0), self.duration))
        t = np.clip(t, 0.0, self.duration)
        which = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        dof = self.pieces[0].c.shape[-1]
        out = [np.empty((len(t), dof)) for _ in range(3)]
        for i in np.unique(which):
            sel = which == i
            local = t[sel] - self.starts[i]
            for k in range(3):
                out[k][sel] = self.pieces[i](local, k)
        ended = t >= self.duration
        out[1][ended], out[2][ended] = 0.0, 0.0
        return tuple(out)

    def _at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ (1, dof) at one time: the piece's cubic on its interval, summed as scipy's PPoly does."""
        i = min(max(bisect_right(self._starts, t) - 1, 0), len(self.pieces) - 1)
        knots = self._knots[i]
        local = t - self._starts[i]
        j = min(max(bisect_right(knots, local) - 1, 0), len(knots) - 2)
        c3, c2, c1, c0 = self.pieces[i].c[:, j]  # highest power first
        s = local - knots[j]
        s2 = s * s
        q = c0 + c1 * s + c2 * s2 + c3 * (s2 * s)
        if t >= self.duration:
            return q[None], np.zeros((1, len(q))), np.zeros((1, len(q)))
        return q[None], (c1 + c2 * s * 2 + c3 * s2 * 3)[None], (c2 * 2 + c3 * s * 6)[None]


class BoxAvoidPlanner(Planner):
    """Gripper path over obstacle faces (ARM record-and-replay), in joint space via closed-form IK."""

    metrics = (
        Metric("max_tip_speed_m_s", "m/s", description="largest gripper tip speed of the plan"),
        Metric("obstacle_merges", "count", description="overlapping obstacles merged for the path"),
        Metric("tip_min_clearance_m", "m", description="smallest tip clearance from an obstacle"),
    )

    def __init__(self, config: BoxAvoidConfig, context: Context):
        self.config, self.robot = config, context.robot
        world = context.world
        base = self.robot.model.base_pose
        objects = [o for o in (world.objects if world else []) if not o.dynamic and not o.mocap]
        if config.obstacles is not None:
            known = {o.name: o for o in objects}
            missing = [n for n in config.obstacles if n not in known]
            if missing:
                raise SettingError("obstacles", f"{missing} are not static objects of the world; "
                                 f"known: {sorted(known) or 'none'}")
            objects = [known[n] for n in config.obstacles]
        rot_b, t_b = base[:3, :3], base[:3, 3]
        self.obstacles: list[Solid] = [  # in the robot base frame, where plans are made
            make_solid(o.shape, tuple(o.size), rot_b.T @ (np.asarray(o.pose.position) - t_b),
                       rot_b.T @ rpy_to_matrix(np.radians(o.pose.rpy_deg)), o.name) for o in objects]
        # the world floor z = 0, in the base frame, raised by the margin: the tip keeps above it
        self.floor = (rot_b[2], config.margin - float(t_b[2])) if (world is None or world.floor) else None
        self.polylines: list[np.ndarray] = []

    def plan(self, request: PlanRequest) -> Plan:
        t0 = time.perf_counter()
        cfg, robot = self.config, request.robot
        q = np.asarray(request.q, float)
        start = robot.fk(q)
        pieces, starts, corners, merges, length, straight = [], [0.0], [q], 0, 0.0, 0.0
        blocked, path_ms = set(), 0.0
        for target in request.targets:
            goal = target.pose
            if goal is None:
                goal = robot.fk(target.q)
            t_path = time.perf_counter()
            try:
                result = plan_path(start[:3, 3], goal[:3, 3], self.obstacles, cfg.margin, cfg.clearance, self.floor)
            except NoPathError as exc:
                raise PlanningError(f"target '{target.name}': {exc}", target=target.name) from exc
            path_ms += (time.perf_counter() - t_path) * 1e3
            a, b = start[:3, 3], goal[:3, 3]
            blocked |= {o.name for o in self.obstacles if o.inflated(cfg.margin).hits_segment(a, b)}
            self.polylines.append(result.path)
            merges += result.merges
            length += result.length
            straight += float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
            keep = cfg.orientation == "keep" or target.position_only
            rots = Rotation.from_matrix(np.stack([start[:3, :3], start[:3, :3] if keep else goal[:3, :3]]))
            turn = Slerp([0.0, 1.0], rots)
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(result.path, axis=0), axis=1))])
            total = max(arc[-1], 1e-12)
            for i in range(len(result.path) - 1):
                a, b = result.path[i], result.path[i + 1]
                piece, q = self._piece(robot, q, a, b, turn, arc[i] / total, arc[i + 1] / total, target.name)
                if piece is None:
                    continue
                pieces.append(piece)
                starts.append(starts[-1] + piece.x[-1])
                corners.append(q)
            start = robot.fk(q)
        if not pieces:  # already there
            pieces.append(CubicSpline([0.0, 1e-3], np.vstack([q, q]), bc_type="clamped"))
            starts.append(1e-3)
        traj = PiecewiseSpline(pieces, np.array(starts))
        # planning_time_ms includes the IK samples along the path; path_planning_ms is the face path alone
        diag = {"planning_time_ms": (time.perf_counter() - t0) * 1e3, "path_planning_ms": path_ms,
                "obstacle_merges": float(merges)}
        details = {"path_length_m": round(length, 6), "straight_length_m": round(straight, 6),
                   "straight_path_blocked_by": sorted(blocked),
                   "polyline_m": np.round(self.polylines[-1], 6).tolist() if self.polylines else []}
        return Plan(traj, diagnostics=diag, waypoints=np.array(corners), details=details)

    def _piece(self, robot, q, a, b, turn, f0, f1, name):
        """One straight piece a→b, rest to rest: its joint spline and the joint values at b."""
        cfg = self.config
        seg = float(np.linalg.norm(b - a))
        if seg < 1e-9:
            return None, q
        duration = PEAK * seg / cfg.speed_m_s
        n = max(4, int(np.ceil(duration * cfg.sample_hz)) + 1)
        u = np.linspace(0.0, 1.0, n)
        s = quintic(u)[0]
        rots = turn(f0 + (f1 - f0) * s).as_matrix()
        lim = robot.model.limits
        qs, prev = [], q
        for k in range(n):
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = rots[k], a + s[k] * (b - a)
            sols = [prev + angular_distance(x, prev) for x in robot.ik(pose, reference=prev)]
            sols = [x for x in sols if np.all(x >= lim.lower) and np.all(x <= lim.upper)]
            if not sols:
                raise PlanningError(f"target '{name}': the gripper cannot reach {np.round(pose[:3, 3], 3).tolist()} m "
                                    "on the way (out of reach or joint limits)", target=name)
            prev = min(sols, key=lambda x: float(np.abs(x - prev).max()))
            qs.append(prev)
        qs = np.array(qs)
        jump = np.abs(np.diff(qs, axis=0)).max()
        if jump > 0.35:
            raise PlanningError(f"target '{name}': the arm would flip its wrist near "
                                f"{np.round(a + 0.5 * (b - a), 3).tolist()} m (a singular configuration); "
                                "choose another gripper orientation", target=name)
        times = u * duration
        spline = CubicSpline(times, qs, bc_type="clamped")
        fine = np.linspace(0.0, duration, 8 * n)
        ratio = float(np.max(np.abs(spline(fine, 1)) / lim.velocity)) / cfg.joint_speed_fraction
        if ratio > 1.0:  # slowing the piece down scales every joint speed by the same factor
            spline = CubicSpline(times * ratio, qs, bc_type="clamped")
        return spline, qs[-1]

    def run_metrics(self, trace) -> dict[str, float]:
        """Where the executed gripper tip went: its clearance from the true obstacles and its peak speed."""
        if not len(trace.q):
            return {}
        tip = self.robot.fk_batch(trace.q)[:, :3, 3]
        out = {}
        if self.obstacles:
            out["tip_min_clearance_m"] = float(min(o.distance(tip).min() for o in self.obstacles))
        if len(tip) > 1:
            speed = np.linalg.norm(np.diff(tip, axis=0), axis=1) / np.diff(trace.t)
            out["max_tip_speed_m_s"] = float(speed.max())
        return out


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("box-avoid", config=BoxAvoidConfig, factory=BoxAvoidPlanner)
