"""Operational-space planners on a workspace look-up table (after Loconsole et al.).

For each target: an unreachable target is replaced by its proxy point (bisection
on the line from the current point); a straight line is used when it stays in
the inner workspace; otherwise a voxel search (the subclass's) finds a path,
which is decimated (one point in n), splined (C2), checked to stay inner (else
smaller n), resampled at 1 mm and timed with a trapezoidal speed profile. A
replan during motion starts from the current *reference* point and blends from
the old trajectory into the new one.
"""

from __future__ import annotations

import time
from abc import abstractmethod
from collections.abc import Callable
from typing import Literal

import numpy as np
from pydantic import Field

from rehabkit.core.kinds.capabilities import WorkspaceTable
from rehabkit.core.kinds.interfaces import Context, Plan, Planner, PlanningError, PlanRequest, StrictModel
from rehabkit.core.kinds.metric import Metric
from rehabkit.workspace.grid import BOUNDARY, INNER, VoxelWorkspace
from rehabkit.workspace.search import SearchFailedError, astar, decimate, path_length
from rehabkit.workspace.trajectory import Junction, Sequence, TimedPath, resample, smooth_path

Search = Callable[[VoxelWorkspace, np.ndarray, np.ndarray], np.ndarray]
FALLBACKS: dict[str, Search] = {"astar": astar, "weighted-astar": lambda ws, a, b: astar(ws, a, b, weight=1.5)}


class VoxelPlannerConfig(StrictModel):
    """Settings every workspace planner shares."""

    resolution: float = Field(0.01, gt=0, description="voxel edge of the look-up table [m]")
    decimation: int = Field(3, ge=1, le=3, description="keep one voxel in n before smoothing (n <= 3)")
    v_max: float = Field(0.15, gt=0, description="cruise speed of the hand [m/s]")
    a_max: float = Field(0.3, gt=0, description="acceleration of the speed profile [m/s^2]")
    junction_s: float = Field(0.5, gt=0, description="blend time from an old trajectory into a new one [s]")
    fallback: Literal["none", "astar", "weighted-astar"] = Field(
        "none", description="search to use when this one fails (greedy searches can get stuck)")


class VoxelPlanner(Planner):
    """Base of the workspace planners; subclasses supply :meth:`search`."""

    metrics = (
        Metric("goals_reached", "count", description="targets reached by the executed motion"),
        Metric("goal_reach_error_max_mm", "mm", description="largest distance from a target when its reach ended"),
        Metric("junction_s", "s", description="time spent joining a new plan to the motion under way"),
        Metric("proxy_targets", "count", description="targets outside the workspace replaced by proxy points"),
        Metric("straight_legs", "count", description="legs planned as a straight line (no search)"),
        Metric("searched_legs", "count", description="legs planned by the search"),
        Metric("path_length_m", "m", description="length of the planned hand path"),
        Metric("decimated_path_length_m", "m", description="path length after decimation"),
        Metric("decimation_used", description="whether the searched path was decimated before smoothing"),
        Metric("workspace_lookup_table_mb", "MB", description="memory of the workspace look-up table"),
        Metric("path_outside_workspace_samples", "count", description="plan samples outside the table"),
        Metric("reference_outside_workspace_samples", "count", description="reference samples outside the table"),
        Metric("proxy_bisection_lookups", "count", description="table look-ups of the proxy point bisection"),
        Metric("proxy_reentry_checks", "count", description="checks of the path re-entering the workspace"),
    )

    space = "cartesian"
    name = "voxel"
    requires = (WorkspaceTable,)

    def __init__(self, config: VoxelPlannerConfig, context: Context):
        robot = context.robot
        self.config = config
        self.robot = robot
        self.ws: VoxelWorkspace = robot.workspace(config.resolution)
        self._active: tuple[float, object] | None = None  # (start time, trajectory) being executed
        self.history: list[tuple[float, float, np.ndarray]] = []  # (start, duration, final goal) of each plan

    @abstractmethod
    def search(self, ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Voxel-centre path from ``start`` to ``goal`` (both inner), or :class:`SearchFailedError`."""

    # -- pieces ---------------------------------------------------------------

    def _snap_inner(self, p: np.ndarray) -> np.ndarray:
        """``p`` if inner, else the nearest inner voxel centre within a few voxels."""
        if self.ws.inner(p):
            return p
        centre = self.ws.index(p[None])[0]
        for radius in range(1, 6):
            r = np.arange(-radius, radius + 1)
            cand = centre + np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
            pts = self.ws.centre(cand)
            ok = self.ws.label(pts) == INNER
            if ok.any():
                pts = pts[ok]
                return pts[np.argmin(np.linalg.norm(pts - p, axis=1))]
        raise PlanningError(f"{self.name}: {np.round(p, 3).tolist()} m is not near the inner workspace")

    def _proxy(self, here: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, int, int]:
        """Nearest inner point to ``target`` on the line from ``here``, by bisection.

        Bisection finds *a* crossing of the workspace surface; one vectorised
        look-up checks that the line does not come back in nearer the target
        (else bisection runs again from there).

        Returns:
            The proxy, the largest number of bisection look-ups, the re-entry checks made.
        """
        proxy, used = self.ws.proxy_point(here, target, level=INNER)
        most, checks = used, 0
        for _ in range(4):
            rest = proxy + np.linspace(0.0, 1.0, 64)[1:, None] * (target - proxy)
            inside = np.flatnonzero(self.ws.label(rest) == INNER)
            checks += 1
            if not len(inside):
                break
            proxy, used = self.ws.proxy_point(rest[inside[-1]], target, level=INNER)
            most = max(most, used)
        return proxy, most, checks

    def _route(self, start: np.ndarray, goal: np.ndarray, diag: dict) -> np.ndarray:
        """Voxel-level route start → goal (both ends exact)."""
        if self.ws.segment_inner(start, goal):
            diag["straight_legs"] = diag.get("straight_legs", 0) + 1
            return np.vstack([start, goal])
        a, b = self._snap_inner(start), self._snap_inner(goal)
        try:
            voxels = self.search(self.ws, a, b)
        except SearchFailedError as exc:
            if self.config.fallback == "none":
                raise PlanningError(f"{self.name}: {exc}", code=exc.kind) from None
            voxels = FALLBACKS[self.config.fallback](self.ws, a, b)
            diag["fallbacks"] = diag.get("fallbacks", 0) + 1
        diag["searched_legs"] = diag.get("searched_legs", 0) + 1
        diag["decimated_path_length_m"] = diag.get("decimated_path_length_m", 0.0) + path_length(
            decimate(voxels, self.config.decimation))
        return np.vstack([start, voxels[1:-1], goal]) if len(voxels) > 2 else np.vstack([start, goal])

    def _smooth(self, route: np.ndarray, diag: dict) -> np.ndarray:
        """Decimate and spline; the largest n <= decimation whose curve stays inner, else the route itself."""
        if len(route) == 2:
            return resample(route, 0.001)
        # ends sit where the arm is and at a proxy, i.e. on the edge of the inner region: there,
        # boundary voxels (still reachable) are accepted for 1.5 voxels; everywhere else inner only
        edge = int(np.ceil(1.5 * self.ws.resolution / 0.001))
        for n in range(self.config.decimation, 0, -1):
            curve = smooth_path(decimate(route, n))
            labels = self.ws.label(curve)
            if np.all(labels[edge:-edge] == INNER) and np.all(labels >= BOUNDARY):
                diag["decimation_used"] = min(diag.get("decimation_used", 3), n)
                return curve
        diag["decimation_used"] = 0  # the voxel polyline itself: inner by construction
        return resample(route, 0.001)

    # -- planning -------------------------------------------------------------

    def plan(self, request: PlanRequest) -> Plan:
        t0 = time.perf_counter()
        diag: dict[str, float] = {}
        old = self._active
        if old is not None and request.t - old[0] < old[1].duration:
            here = old[1].sample([request.t - old[0]])[0][0]  # the current reference point
        else:
            old = None
            here = self.robot.fk(request.q)[:3, 3]
        legs, goals, proxies, checks = [], [], 0, 0
        for target in request.targets:
            if target.pose is None:
                raise PlanningError(f"{self.name}: target '{target.name}' has no position")
            goal = target.pose[:3, 3]
            if self.ws.reachable(goal):
                goal = self._snap_inner(goal)  # reachable, maybe on the boundary: the nearest inner voxel
            else:
                goal, used, extra = self._proxy(here, goal)
                proxies = max(proxies, used)
                checks = max(checks, extra)
                diag["proxy_targets"] = diag.get("proxy_targets", 0) + 1
            curve = self._smooth(self._route(here, goal, diag), diag)
            legs.append(TimedPath(curve, self.config.v_max, self.config.a_max))
            goals.append(goal)
            here = goal
        traj = Sequence(legs)
        if old is not None:
            traj = self._join(old, request.t, traj, diag)
        self._active = (request.t, traj)
        self.history.append((request.t, traj.duration, goals[-1] if goals else here))
        diag["proxy_bisection_lookups"] = proxies
        diag["proxy_reentry_checks"] = checks
        diag["path_length_m"] = float(sum(leg.length for leg in legs))
        diag["planning_time_ms"] = (time.perf_counter() - t0) * 1e3
        return Plan(traj, diag, np.array(goals))

    def _join(self, old: tuple[float, object], t: float, new, diag: dict):
        """Blend into the new trajectory; shorten the blend if the blended curve would leave the workspace."""
        blend = self.config.junction_s
        while blend >= 0.05:
            joined = Junction(old[1], t - old[0], new, blend)
            x = joined.sample(np.linspace(0.0, blend, 200))[0]
            if np.all(self.ws.label(x) >= BOUNDARY):
                diag["junction_s"] = blend
                return joined
            blend /= 2
        diag["junction_s"] = 0.0
        return new

    def visuals(self) -> dict[str, np.ndarray]:
        return {"workspace_boundary": self.ws.boundary_points()}

    def run_metrics(self, trace) -> dict[str, float]:
        """Where the executed and the reference hand paths went relative to the workspace."""
        if trace.x is None or not len(trace.x):
            return {}
        ref = self.ws.label(trace.x_ref)
        done = self.ws.label(trace.x)
        out = {
            "reference_outside_workspace_samples": int((ref == 0).sum()),
            "path_outside_workspace_samples": int((done == 0).sum()),
            "workspace_lookup_table_mb": self.ws.nbytes / 1e6,
        }
        # how close the hand got to each plan's goal (a proxy, when the target was out of reach)
        errors = []
        ends = [h[0] for h in self.history[1:]] + [float(trace.t[-1]) + 1e-9]
        for (start, duration, goal), end in zip(self.history, ends):
            if start + duration <= end:  # the plan had time to finish before the next one
                k = min(int(np.searchsorted(trace.t, end)) - 1, len(trace.t) - 1)
                errors.append(float(np.linalg.norm(trace.x[k] - goal)))
        if errors:
            out["goal_reach_error_max_mm"] = max(errors) * 1e3
            out["goals_reached"] = len(errors)
        return out

