"""Collision-free joint-space paths for any robot: OMPL's RRT-Connect, RRT* or PRM, every state checked against
the scenario's world by MuJoCo's collision detection, the path shortcut by OMPL's simplifier and timed within
the joints' limits.

Targets are joint values or Cartesian poses (solved by the robot's IK, the nearest solution free of the world).
Each leg between targets is planned on its own; the path between its vertices is straight in joint space and
run rest to rest (:mod:`rehabkit.cspace.timing`), so the arm moves along exactly the segments that were checked.
"""

from __future__ import annotations

import time
from typing import Literal

import numpy as np
from pydantic import Field

from rehabkit.planning import SceneCollision, seed_ompl
from rehabkit.plugin import (
    Context,
    Metric,
    Plan,
    Planner,
    PlanningError,
    PlanRequest,
    StrictModel,
    hookimpl,
    joint_waypoints,
)
from rehabkit.trajectories import RestToRestPath, rest_to_rest_durations

ALGORITHMS = {"rrt-connect": "RRTConnect", "rrt-star": "RRTstar", "prm": "PRM"}


class OmplJointConfig(StrictModel):
    """Sampling planner, collision checks and time law."""

    algorithm: Literal["rrt-connect", "rrt-star", "prm"] = Field(
        "rrt-connect", description="OMPL planner: RRT-Connect stops at the first path; RRT* and PRM improve it for "
                                   "the whole time_limit_s")
    time_limit_s: float = Field(1.0, gt=0, description="planning time allowed per leg [s]")
    clearance_m: float = Field(0.01, ge=0, description="distance below which a link counts as touching the world [m]")
    check_step_deg: float = Field(1.0, gt=0, description="largest joint step between checked states on an edge [deg]")
    simplify: bool = Field(True, description="shortcut the path (OMPL's vertex reduction and rope shortcutting)")
    speed_fraction: float = Field(0.5, gt=0, le=1, description="peak joint speed as a fraction of its limit")
    acceleration_deg_s2: float = Field(300.0, gt=0, description="peak joint acceleration [deg/s^2]")
    seed: int | None = Field(None, description="OMPL's seed (default: drawn from the scenario's seed)")


class OmplJointPlanner(Planner):
    """Collision-checked OMPL paths in joint space, shortcut and timed rest to rest at each vertex."""

    metrics = (
        Metric("planning_time_s", "s", "wall", description="time to plan, all legs"),
        Metric("path_length_rad", "rad", description="joint-space length of the planned path"),
        Metric("path_vertices", "count", description="vertices of the planned path, targets included"),
        Metric("states_checked", "count", description="states checked for collision by MuJoCo"),
    )

    def __init__(self, config: OmplJointConfig, context: Context):
        self.config = config
        self.robot = context.robot
        self.checker = SceneCollision(self.robot.model, context.world, config.clearance_m)
        self.seed = int(context.rng.integers(1, 2**31)) if config.seed is None else config.seed
        self.plans = 0

    def plan(self, request: PlanRequest) -> Plan:
        t0, checks0 = time.perf_counter(), self.checker.checks
        seed_ompl(self.seed + 7919 * self.plans)  # each plan reproducible whatever ran before it
        self.plans += 1
        start = np.asarray(request.q, float)
        self._require_free(start, "the start posture")
        wp = joint_waypoints(request.targets, request.robot, start, accept=self.checker.free)
        points, target_index = [start], [0]
        for target, goal in zip(request.targets, wp.q):
            if target.q is not None:
                self._require_free(goal, f"target '{target.name}'")
            if np.abs(goal - points[-1]).max() > 1e-9:  # a target the arm is at already adds no leg
                points.extend(self._leg(points[-1], goal, target.name)[1:])
            target_index.append(len(points) - 1)
        path = np.array(points)
        lim = self.robot.model.limits
        durations = rest_to_rest_durations(path, self.config.speed_fraction * lim.velocity,
                                           np.full(len(start), np.radians(self.config.acceleration_deg_s2)))
        traj = RestToRestPath(path, durations)
        diag = {
            "planning_time_s": time.perf_counter() - t0,
            "path_length_rad": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()),
            "path_vertices": float(len(path)),
            "states_checked": float(self.checker.checks - checks0),
        }
        return Plan(traj, diag, path[target_index], waypoint_times=traj.breaks[target_index])

    def _require_free(self, q: np.ndarray, what: str) -> None:
        hits = self.checker.hits(q)
        if hits:
            h = min(hits, key=lambda h: h.distance)
            raise PlanningError(f"{what} puts '{h.robot_geom}' {-h.distance * 1000:.0f} mm into '{h.world_geom}'"
                                if h.distance < 0 else
                                f"{what} puts '{h.robot_geom}' {h.distance * 1000:.0f} mm from '{h.world_geom}', "
                                f"nearer than clearance_m ({self.config.clearance_m} m)")

    def _leg(self, a: np.ndarray, b: np.ndarray, name: str) -> np.ndarray:
        """A collision-free polyline from ``a`` to ``b`` (both free), shortcut."""
        from ompl import base as ob
        from ompl import geometric as og

        lim, n = self.robot.model.limits, len(a)
        step = np.radians(self.config.check_step_deg)
        if self._segment_free(a, b, step):  # nothing in the way: no search needed
            return np.array([a, b])
        space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i in range(n):
            bounds.setLow(i, float(lim.lower[i]))
            bounds.setHigh(i, float(lim.upper[i]))
        space.setBounds(bounds)
        ss = og.SimpleSetup(space)
        free = self.checker.free
        ss.setStateValidityChecker(lambda s: free(np.fromiter((s[i] for i in range(n)), float, n)))
        si = ss.getSpaceInformation()
        si.setStateValidityCheckingResolution(step / space.getMaximumExtent())
        start, goal = space.allocState(), space.allocState()
        for i in range(n):
            start[i], goal[i] = float(a[i]), float(b[i])
        ss.setStartAndGoalStates(start, goal)
        ss.setPlanner(getattr(og, ALGORITHMS[self.config.algorithm])(si))
        if not (ss.solve(self.config.time_limit_s) and ss.haveExactSolutionPath()):
            raise PlanningError(f"target '{name}': {self.config.algorithm} found no collision-free path in "
                                f"{self.config.time_limit_s:g} s (raise planner.time_limit_s, or the target may "
                                "be walled off)", target=name)
        path = ss.getSolutionPath()
        if self.config.simplify:
            simplifier = og.PathSimplifier(si)
            simplifier.reduceVertices(path)
            simplifier.ropeShortcutPath(path)
            simplifier.collapseCloseVertices(path)
        points = np.array([[path.getState(k)[i] for i in range(n)] for k in range(path.getStateCount())])
        for p, q in zip(points[:-1], points[1:]):  # the simplifier checks too; this makes sure at our resolution
            if not self._segment_free(p, q, step):
                raise PlanningError(f"target '{name}': the simplified path touches the world (internal check)",
                                    target=name)
        return points

    def _segment_free(self, a: np.ndarray, b: np.ndarray, step: float) -> bool:
        k = max(1, int(np.ceil(np.abs(b - a).max() / step)))
        return self.checker.first_collision(a + np.linspace(0, 1, k + 1)[:, None] * (b - a)) < 0


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("ompl-joint", config=OmplJointConfig, factory=OmplJointPlanner)
