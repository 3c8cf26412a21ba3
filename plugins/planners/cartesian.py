"""Straight lines in task space for any robot: the hand moves from where it is through each target in a straight
line (orientation turned by slerp), on a minimum-jerk time law, with the robot's IK solved along the way.

Each segment is sampled every ``step_m`` (and every ``step_deg`` of turn); each sample's joint values continue
the previous ones (a local IK descent from them; the robot's own IK, nearest solution, where that fails). A jump
between samples means the line crosses a singularity or leaves the reachable space: refused, with where. A
segment's duration is stretched until no joint exceeds ``speed_fraction`` of its velocity limit, and the joint
samples are joined by a C2 multi-cubic (rest at both ends) — the reference the joint controller tracks. With
obstacles in the world each sample is checked against them by MuJoCo (straight lines do not go around things:
add via points).
"""

from __future__ import annotations

import contextlib

import numpy as np
from pydantic import Field

from rehabkit.plugin import (
    Context,
    Metric,
    Plan,
    Planner,
    PlanningError,
    PlanRequest,
    SettingError,
    StrictModel,
    Target,
    angle_axis,
    hookimpl,
    unreachable,
)

from .multi_cubic import MultiCubicTrajectory, solve_multi_cubic


class CartesianConfig(StrictModel):
    """Hand speed, sampling and limits of straight-line task-space motion."""

    speed_m_s: float = Field(0.15, gt=0, description="mean hand speed along a segment [m/s]")
    turn_deg_s: float = Field(45.0, gt=0, description="mean turning speed of the hand along a segment [deg/s]")
    segment_durations: list[float] | None = Field(
        None, description="[s] per segment (one per target), instead of speed_m_s/turn_deg_s; still stretched "
                          "to respect speed_fraction")
    step_m: float = Field(0.01, gt=0, description="IK sample spacing along a segment [m]")
    step_deg: float = Field(3.0, gt=0, description="IK sample spacing in hand rotation [deg]")
    speed_fraction: float = Field(0.8, gt=0, le=1, description="largest joint speed as a fraction of its limit")
    jump_deg: float = Field(10.0, gt=0, description="largest joint change between two IK samples [deg]")
    clearance_m: float | None = Field(0.005, ge=0, description="check every sample against the world's objects "
                                                               "with this clearance [m] (null: no check)")


def min_jerk(tau: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ on τ ∈ [0, 1] (rest at both ends)."""
    return tau**3 * (10 - 15 * tau + 6 * tau**2)


def slerp(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotations (len(s), 3, 3) turning from ``a`` to ``b`` about one fixed axis, a fraction ``s`` of the way."""
    angle, axis = angle_axis(a.T @ b)
    if axis is None:
        return np.repeat(a[None], len(s), axis=0)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    th = (np.asarray(s) * angle)[:, None, None]
    return a @ (np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K))


class CartesianPlanner(Planner):
    """Straight task-space segments through the targets, minimum-jerk, IK along the way (any robot)."""

    metrics = (
        Metric("ik_samples", "count", description="poses solved by IK along the segments"),
        Metric("path_length_m", "m", description="length of the hand's planned path"),
        Metric("stretched_segments", "count", description="segments slowed down to keep joint speeds within limits"),
    )

    def __init__(self, config: CartesianConfig, context: Context):
        if config.segment_durations is not None and any(t <= 0 for t in config.segment_durations):
            raise SettingError("segment_durations", "must all be > 0")
        self.config = config
        self.robot = context.robot
        self.checker = None
        world = context.world
        if config.clearance_m is not None and world is not None and (world.objects or world.floor):
            from rehabkit.planning import SceneCollision

            self.checker = SceneCollision(self.robot.model, world, config.clearance_m)

    def plan(self, request: PlanRequest) -> Plan:
        cfg, robot = self.config, request.robot
        targets = request.targets
        if cfg.segment_durations is not None and len(cfg.segment_durations) != len(targets):
            raise PlanningError(f"segment_durations has {len(cfg.segment_durations)} values; the plan goes to "
                                f"{len(targets)} target(s) ({', '.join(t.name for t in targets)}), one each")
        q = np.asarray(request.q, float)
        pose = robot.fk(q)
        qs, times, ends, stretched, length = [q], [0.0], [0], 0, 0.0
        for k, target in enumerate(targets):
            goal = target.pose if target.pose is not None else robot.fk(target.q)
            free = target.free if target.pose is not None else ""
            dist = float(np.linalg.norm(goal[:3, 3] - pose[:3, 3]))
            turn = 0.0 if free == "xyz" else float(np.degrees(angle_axis(pose[:3, :3].T @ goal[:3, :3])[0]))
            if dist < 1e-6 and turn < 1e-3:
                ends.append(len(qs) - 1)
                continue
            n = max(4, int(np.ceil(max(dist / cfg.step_m, turn / cfg.step_deg))))
            s = min_jerk(np.arange(1, n + 1) / n)  # samples uniform in time: denser where the hand is slow
            rots = slerp(pose[:3, :3], goal[:3, :3], s)
            seg = []
            for i in range(n):
                want = np.eye(4)
                want[:3, :3], want[:3, 3] = rots[i], pose[:3, 3] + s[i] * (goal[:3, 3] - pose[:3, 3])
                seg.append(self._follow(robot, want, seg[-1] if seg else qs[-1], free, target, s[i]))
            if target.q is not None and np.abs(seg[-1] - target.q).max() > np.radians(1):
                raise PlanningError(f"target '{target.name}': the straight line ends in another posture than its "
                                    "joint values (another IK branch)", target=target.name,
                                    fix="give it as a position")
            seg = np.array(seg)
            T = cfg.segment_durations[k] if cfg.segment_durations else max(dist / cfg.speed_m_s,
                                                                           turn / cfg.turn_deg_s, 0.2)
            dq = np.abs(np.diff(np.vstack([qs[-1], seg]), axis=0))
            dt = T * np.diff(np.concatenate([[0.0], np.arange(1, n + 1) / n]))
            ratio = float((dq / dt[:, None] / (cfg.speed_fraction * robot.model.limits.velocity)).max())
            if ratio > 1:
                T, stretched = T * ratio * 1.05, stretched + 1  # finite differences underrate the spline's peak
            qs.extend(seg)
            times.extend(times[-1] + T * np.arange(1, n + 1) / n)
            ends.append(len(qs) - 1)
            length += dist
            pose = robot.fk(seg[-1])
        points, times = np.array(qs), np.array(times)
        if len(points) == 1:
            points, times = np.vstack([points, points]), np.array([0.0, 0.2])
            ends = [min(e, 1) for e in ends]
        traj = MultiCubicTrajectory(solve_multi_cubic(points, np.diff(times)), np.diff(times))
        diag = {"ik_samples": float(len(points) - 1), "path_length_m": length, "stretched_segments": float(stretched)}
        return Plan(traj, diag, points[ends], waypoint_times=times[ends])

    def _follow(self, robot, pose: np.ndarray, prev: np.ndarray, free: str, target: Target, s: float) -> np.ndarray:
        """Joint values at one sample of the line, continuing ``prev``."""
        q = None
        with contextlib.suppress(NotImplementedError):  # no Pinocchio model (closed loops): the robot's own IK
            q = robot.numeric_ik.track(pose, prev, free)
        if q is None:
            sols = robot.solve_ik(pose, reference=prev, free=free)
            if not sols:
                raise PlanningError(unreachable(target, robot).replace(
                    "is out of reach", f"is not reached in a straight line: {s:.0%} of the way the hand leaves "
                                       "the reachable space", 1), target=target.name)
            q = sols[0]
        jump = float(np.degrees(np.abs(q - prev).max()))
        if jump > self.config.jump_deg:
            raise PlanningError(f"target '{target.name}': {s:.0%} of the way along the straight line the arm must "
                                f"turn a joint by {jump:.0f} deg at once (a singularity or a joint limit)",
                                target=target.name, fix="add a via point or go in joint space")
        if self.checker is not None:
            hits = self.checker.hits(q)
            if hits:
                h = min(hits, key=lambda h: h.distance)
                raise PlanningError(f"target '{target.name}': {s:.0%} of the way along the straight line "
                                    f"'{h.robot_geom}' comes within {max(h.distance, 0) * 1000:.0f} mm of "
                                    f"'{h.world_geom}' (clearance_m {self.config.clearance_m})",
                                    target=target.name, fix="add a via point")
        return q


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("cartesian", config=CartesianConfig, factory=CartesianPlanner)
