"""Collision-free joint paths by RRT + genetic optimisation (after Carbone et al., CaPaMan).

Set-up (once): the scenario's static obstacles are rasterised into Ψ (grown by
the robot's link radius, as its links are represented by axis points), and
the joint matrix Θ marks every configuration of an ε-grid of joint space
whose cluster points all miss Ψ; ρ is its distance transform.
Planning: the task points (IK of the task configurations) split the task into
legs; OMPL's RRT-Connect draws several collision-free polylines per leg (seeded,
so runs repeat); they seed a population the GA of :mod:`rehabkit.cspace.genetic`
improves. The best path is resampled to ``points`` configurations (task points
kept) and timed by a C2 multi-cubic with ``point_interval_s`` between points.
"""

from __future__ import annotations

import time

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from pydantic import Field
from rehabkit_plugins.robots.contracts import ClusterPoints
from scipy import ndimage

from rehabkit.planning import GAConfig, JointMatrix, PathGA, build_joint_matrix, rasterise, resample, seed_ompl
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

from .multi_cubic import MultiCubicTrajectory, solve_multi_cubic


class RrtGaConfig(StrictModel):
    """Grid, RRT, GA and timing settings."""

    epsilon_deg: float = Field(3.0, gt=0, description="ε: joint-matrix grid step")
    psi_resolution: float = Field(0.005, gt=0, description="Ψ cell edge [m]")
    rrt_paths_per_leg: int = Field(4, ge=1)
    rrt_time_s: float = Field(0.2, gt=0, description="time limit of one RRT-Connect run")
    rrt_range_deg: float = Field(10.0, gt=0)
    population: int = Field(30, ge=4)
    generations: int = Field(60, ge=0)
    beta: float = Field(0.2, ge=0, description="fitness penalty per configuration closer than delta")
    delta_deg: float = Field(8.0, ge=0, description="δ: joint-space clearance below which β applies")
    points: int = Field(21, ge=2, description="trajectory points, task points included")
    point_interval_s: float = Field(0.45, gt=0, description="time between trajectory points [s]")
    seed: int | None = Field(None, description="default: the scenario's seed")


class RrtGaPlanner(Planner):
    """Joint-space paths around obstacles: joint matrix Θ, OMPL RRT-Connect population, genetic optimisation."""

    requires = (ClusterPoints,)  # the collision map is built from points on the moving body
    metrics = (
        Metric("joint_matrix_setup_s", "s", "wall", description="time to build the joint matrix"),
        Metric("joint_matrix_free_fraction", description="share of the joint matrix free of obstacles"),
        Metric("rrt_paths", "count", description="RRT-Connect paths in the GA's first population"),
        Metric("generations", "count", description="GA generations run"),
        Metric("fitness_best_rrt", description="best fitness among the RRT paths"),
        Metric("fitness_best_ga", description="best fitness after the GA"),
        Metric("path_length_rrt_rad", "rad", description="joint-space length of the best RRT path"),
        Metric("path_length_ga_rad", "rad", description="joint-space length of the GA's path"),
        Metric("clearance_rrt_deg", "deg", description="joint-space clearance of the best RRT path"),
        Metric("clearance_ga_deg", "deg", description="joint-space clearance of the GA's path"),
        Metric("direct_motion_collides", description="whether the straight joint motion would collide"),
        Metric("ompl_seed", description="OMPL's seed for the plan"),
        Metric("tool_clearance_m", "m", description="smallest tool clearance from the obstacles"),
        Metric("trajectory_colliding_samples", "count", description="planned trajectory samples in collision"),
        Metric("executed_colliding_configurations", "count", description="executed configurations in collision"),
        Metric("executed_min_joint_clearance_deg", "deg", description="smallest joint-space clearance executed"),
    )

    def __init__(self, config: RrtGaConfig, context: Context):
        self.config = config
        self.robot = context.robot
        self.seed = context.rng.integers(2**31) if config.seed is None else config.seed
        lim = self.robot.model.limits
        t0 = time.perf_counter()
        corners = np.stack(
            np.meshgrid(*[np.linspace(lo, hi, 5) for lo, hi in zip(lim.lower, lim.upper)], indexing="ij"), -1
        ).reshape(-1, len(lim.lower))
        pts = self.robot.cluster_points(corners).reshape(-1, 3)
        margin = 0.03
        self.psi = rasterise(
            context.world.objects,
            self.robot.model.base_pose,
            pts.min(0) - margin,
            pts.max(0) + margin,
            config.psi_resolution,
            inflate=self.robot.link_radius,
        )
        self.psi_exact = rasterise(
            context.world.objects,
            self.robot.model.base_pose,
            pts.min(0) - margin,
            pts.max(0) + margin,
            config.psi_resolution / 2,
        )
        self.theta: JointMatrix = build_joint_matrix(
            self.robot.cluster_points, self.psi, lim.lower, lim.upper, np.radians(config.epsilon_deg)
        )
        self.setup_time = time.perf_counter() - t0
        self.ga_config = GAConfig(config.population, config.generations, config.beta, np.radians(config.delta_deg))
        self.last_path: np.ndarray | None = None
        self.plans = 0  # plans made so far: each plan's RRT streams are seeded by the seed and this count

    # -- RRT -------------------------------------------------------------------

    def _rrt_paths(self, a: np.ndarray, b: np.ndarray, runs: int) -> list[np.ndarray]:
        n = len(a)
        space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i, (lo, hi) in enumerate(zip(self.theta.lower, self.theta.upper)):
            bounds.setLow(i, float(lo))
            bounds.setHigh(i, float(hi))
        space.setBounds(bounds)
        theta = self.theta
        ss = og.SimpleSetup(space)
        ss.setStateValidityChecker(self._checker())
        si = ss.getSpaceInformation()
        extent = float(np.linalg.norm(theta.upper - theta.lower))
        si.setStateValidityCheckingResolution(0.5 * theta.step / extent)
        start, goal = space.allocState(), space.allocState()
        for i in range(n):
            start[i], goal[i] = float(a[i]), float(b[i])
        ss.setStartAndGoalStates(start, goal)
        paths = []
        for _ in range(runs):
            planner = og.RRTConnect(si)
            planner.setRange(np.radians(self.config.rrt_range_deg))
            ss.setPlanner(planner)
            ss.clear()
            if ss.solve(self.config.rrt_time_s) and ss.haveExactSolutionPath():
                p = ss.getSolutionPath()
                paths.append(np.array([[p.getState(k)[i] for i in range(n)] for k in range(p.getStateCount())]))
        return paths

    def _checker(self):
        """OMPL's validity callback: a scalar look-up in Θ (it runs thousands of times per plan)."""
        theta = self.theta
        (nx, ny, nz), lo, step = theta.free.shape, theta.lower.tolist(), theta.step
        flat = theta.free.ravel().tolist()

        def valid(s) -> bool:
            i, j, k = (
                int((s[0] - lo[0]) / step + 0.5),
                int((s[1] - lo[1]) / step + 0.5),
                int((s[2] - lo[2]) / step + 0.5),
            )
            return 0 <= i < nx and 0 <= j < ny and 0 <= k < nz and flat[(i * ny + j) * nz + k]

        return valid

    # -- planning --------------------------------------------------------------

    def plan(self, request: PlanRequest) -> Plan:
        t0 = time.perf_counter()
        ompl_seed = seed_ompl(int(self.seed) + 7919 * self.plans)  # the first plan: the seed itself
        self.plans += 1
        wp = joint_waypoints(request.targets, request.robot, request.q).q
        if not self.theta.is_free(wp).all():
            raise PlanningError("rrt-ga: a task point itself collides with the obstacles")
        rng = np.random.default_rng(self.seed)
        legs = []
        for k in range(len(wp) - 1):
            found = self._rrt_paths(wp[k], wp[k + 1], self.config.rrt_paths_per_leg)
            if not found:
                raise PlanningError(
                    f"rrt-ga: RRT-Connect found no path for leg {k + 1} in "
                    f"{self.config.rrt_time_s} s x {self.config.rrt_paths_per_leg}"
                )
            legs.append(found)
        t_rrt = time.perf_counter()
        population = [
            [legs[k][rng.integers(len(legs[k]))] for k in range(len(legs))] for _ in range(self.config.population)
        ]
        ga = PathGA(self.theta, self.ga_config, rng)
        raw_fit = np.array([ga.fitness(p) for p in population])
        best_raw = population[int(np.argmin(raw_fit))]
        result = ga.run(population)
        t_ga = time.perf_counter()
        points = self._points(result.best)
        durations = np.full(len(points) - 1, self.config.point_interval_s)
        traj = MultiCubicTrajectory(solve_multi_cubic(points, durations), durations)
        check = traj.sample(np.arange(0.0, traj.duration, 0.002))[0]
        direct = np.vstack([resample(np.vstack([wp[k], wp[k + 1]]), self.theta.step / 2) for k in range(len(wp) - 1)])
        self.last_path = points
        diag = {
            "planning_time_ms": (time.perf_counter() - t0) * 1e3,
            "rrt_time_ms": (t_rrt - t0) * 1e3,
            "ga_time_ms": (t_ga - t_rrt) * 1e3,
            "joint_matrix_setup_s": self.setup_time,
            "joint_matrix_free_fraction": float(self.theta.free.mean()),
            "generations": self.config.generations,
            "rrt_paths": float(sum(len(x) for x in legs)),
            "fitness_best_rrt": float(raw_fit.min()),
            "fitness_best_ga": result.fitness,
            "path_length_rrt_rad": ga.length(best_raw),
            "path_length_ga_rad": ga.length(result.best),
            "clearance_rrt_deg": float(np.degrees(ga.min_clearance(best_raw))),
            "clearance_ga_deg": float(np.degrees(ga.min_clearance(result.best))),
            "direct_motion_collides": float(not self.theta.is_free(direct).all()),
            "trajectory_colliding_samples": float((~self.theta.is_free(check)).sum()),
            "ompl_seed": float(ompl_seed),
        }
        return Plan(traj, diag, points, {"fitness_per_generation": result.history})

    def _points(self, path: list[np.ndarray]) -> np.ndarray:
        """``points`` configurations along the path, task points included, segments shared by leg length."""
        lengths = np.array([np.linalg.norm(np.diff(leg, axis=0), axis=1).sum() for leg in path])
        segments = np.maximum(1, np.round(lengths / lengths.sum() * (self.config.points - 1)).astype(int))
        while segments.sum() > self.config.points - 1:
            segments[np.argmax(segments)] -= 1
        while segments.sum() < self.config.points - 1:
            segments[np.argmax(lengths / segments)] += 1
        out = [path[0][0]]
        for leg, n in zip(path, segments):
            dense = resample(leg, 1e-3)
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
            at = np.linspace(0.0, s[-1], n + 1)[1:]
            out += [np.array([np.interp(x, s, dense[:, j]) for j in range(dense.shape[1])]) for x in at]
        return np.array(out)

    def joint_space_visuals(self) -> dict[str, np.ndarray]:
        """The colliding region of Θ, by its boundary cells (joint values)."""
        blocked = ~self.theta.free
        inner = ndimage.binary_erosion(blocked, border_value=1)
        return {"colliding_region": self.theta.lower + np.argwhere(blocked & ~inner) * self.theta.step}

    def run_metrics(self, trace) -> dict[str, float]:
        """Clearances of the executed motion: joint space (ρ) and the tool's, in metres, to the true obstacles."""
        if not len(trace.q):
            return {}
        q = trace.q[:: max(1, len(trace.q) // 2000)]
        tool = self.robot.cluster_points(q)[:, -24:, :]  # the tool's axis points
        tool_clear = self.psi_exact.clearance(tool).min() - self.robot.config.tool_radius
        return {
            "executed_min_joint_clearance_deg": float(np.degrees(self.theta.clearance(q).min())),
            "executed_colliding_configurations": float((~self.theta.is_free(q)).sum()),
            "tool_clearance_m": float(tool_clear),
        }


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("rrt-ga", config=RrtGaConfig, factory=RrtGaPlanner)
