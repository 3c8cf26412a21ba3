"""Multi-cubic joint trajectory through via points (after Li et al., HIT).

One cubic per segment per joint, ``q_j(τ) = a + bτ + cτ² + dτ³`` on local time
τ ∈ [0, t_j]. Conditions: rest at the first and last point, and position,
velocity and acceleration continuous at every interior via point — 4m
equations for m segments, solved as one linear system shared by all joints.
(The paper's acceleration condition at B is misprinted; continuity means
``2c_{j+1} = 2c_j + 6 d_j t_j``.)
"""

from __future__ import annotations

import numpy as np
from pydantic import ConfigDict, Field

from rehabkit.plugin import (
    Context,
    Metric,
    Plan,
    Planner,
    PlanningError,
    PlanRequest,
    SettingError,
    StrictModel,
    hookimpl,
    joint_waypoints,
)


def cubic_system(durations: np.ndarray) -> np.ndarray:
    """The 4m×4m matrix whose solution is the coefficients [a, b, c, d] of each segment."""
    m = len(durations)
    A = np.zeros((4 * m, 4 * m))
    row = 0

    def put(seg: int, coeffs: list[float], sign: float = 1.0) -> None:
        A[row, 4 * seg : 4 * seg + 4] += sign * np.asarray(coeffs)

    put(0, [1, 0, 0, 0])  # q(0) = first point
    row += 1
    put(0, [0, 1, 0, 0])  # q'(0) = 0
    row += 1
    for j in range(m):
        t = durations[j]
        pos_end, vel_end, acc_end = [1, t, t * t, t**3], [0, 1, 2 * t, 3 * t * t], [0, 0, 2, 6 * t]
        put(j, pos_end)  # end of segment j reaches via point j+1
        row += 1
        if j == m - 1:
            put(j, vel_end)  # rest at the last point
            row += 1
            break
        put(j + 1, [1, 0, 0, 0])  # segment j+1 starts at via point j+1
        row += 1
        put(j, vel_end)
        put(j + 1, [0, 1, 0, 0], -1.0)  # velocity continuous
        row += 1
        put(j, acc_end)
        put(j + 1, [0, 0, 2, 0], -1.0)  # acceleration continuous
        row += 1
    return A


def solve_multi_cubic(points: np.ndarray, durations: np.ndarray, v0: np.ndarray | None = None) -> np.ndarray:
    """Coefficients, shape (m, 4, dof), for via points (m+1, dof) and segment durations (m,); the motion starts
    at velocity ``v0`` (default: at rest) and ends at rest."""
    m = len(durations)
    if points.shape[0] != m + 1:
        raise ValueError(f"{points.shape[0]} via points need {points.shape[0] - 1} durations, got {m}")
    rhs = np.zeros((4 * m, points.shape[1]))
    rhs[0] = points[0]
    if v0 is not None:
        rhs[1] = v0
    r = 2
    for j in range(m):
        rhs[r] = points[j + 1]
        if j == m - 1:
            break
        rhs[r + 1] = points[j + 1]
        r += 4
    return np.linalg.solve(cubic_system(durations), rhs).reshape(m, 4, -1)


class MultiCubicTrajectory:
    """Piecewise cubic joint trajectory: per segment ``a + b τ + c τ² + d τ³`` (τ from the segment's start).

    Evaluated with numpy by Horner's rule (scipy's PPoly did the same, but importing scipy.interpolate cost
    ~0.5 s of every run's start; tests compare the two).
    """

    def __init__(self, coeffs: np.ndarray, durations: np.ndarray):
        self.coeffs, self.durations = coeffs, np.asarray(durations, dtype=float)
        self.breaks = np.concatenate([[0.0], np.cumsum(self.durations)])
        self.duration = float(self.breaks[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raw = np.atleast_1d(np.asarray(t, dtype=float))
        t = np.clip(raw, 0.0, self.duration)
        # the segment holding each time (a time on a via point belongs to the segment it starts)
        seg = np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, len(self.durations) - 1)
        tau = (t - self.breaks[seg])[:, None]
        a, b, c, d = (self.coeffs[seg, i] for i in range(4))
        q = a + tau * (b + tau * (c + tau * d))
        qd = b + tau * (2.0 * c + 3.0 * tau * d)
        qdd = 2.0 * c + 6.0 * tau * d
        after = raw > self.duration
        qd[after] = 0.0
        qdd[after] = 0.0
        return q, qd, qdd

    def continuity(self) -> np.ndarray:
        """Jumps at interior via points: (m-1, 3, dof) of position, velocity, acceleration."""
        out = []
        for j in range(len(self.durations) - 1):
            t = self.durations[j]
            a, b, c, d = self.coeffs[j]
            end = np.array([a + b * t + c * t * t + d * t**3, b + 2 * c * t + 3 * d * t * t, 2 * c + 6 * d * t])
            a2, b2, c2, _ = self.coeffs[j + 1]
            out.append(np.abs(end - np.array([a2, b2, 2 * c2])))
        return np.array(out).reshape(-1, 3, self.coeffs.shape[2])


class MultiCubicConfig(StrictModel):
    """Segment durations of a multi-cubic trajectory."""

    # built where first used: the registry's model of the plugin (this one with its `type`), built as it is
    # registered, is what a scenario is validated with (~0.5 ms less of every run's start)
    model_config = ConfigDict(defer_build=True)

    segment_durations: list[float] = Field(min_length=1, description="[s], one per segment between via points")
    start_from_current: bool = Field(
        False, description="prepend the current joint state as the first via point, leaving at the current "
                           "velocity (for replanning mid-motion)"
    )


class MultiCubicPlanner(Planner):
    """Multi-cubic C2 joint trajectory through via points, rest at both ends (HIT)."""

    metrics = (
        Metric("continuity_*", "deg, deg/s, deg/s^2", description="jump at an interior via point "
               "(continuity_<via>_{position_deg,velocity_deg_s,acceleration_deg_s2}; continuity_max_…: the largest)"),
        Metric("ik_roundtrip_position_error_m", "m", description="largest hand position error of the IK solutions"),
        Metric("ik_roundtrip_orientation_error_deg", "deg",
               description="largest hand orientation error of the IK solutions"),
    )

    def __init__(self, config: MultiCubicConfig, context: Context | None = None):
        if any(t <= 0 for t in config.segment_durations):
            raise SettingError("segment_durations", "every segment duration must be > 0")
        self.config = config

    def plan(self, request: PlanRequest) -> Plan:
        targets = request.targets
        wp = joint_waypoints(targets, request.robot, request.q)
        points, names = wp.q, [t.name for t in targets]
        if self.config.start_from_current:
            points, names = np.vstack([request.q, points]), ["current", *names]
        durations = np.asarray(self.config.segment_durations, dtype=float)
        if len(durations) != len(points) - 1:
            raise PlanningError(
                f"multi-cubic: {len(points)} via points ({', '.join(names)}) need {len(points) - 1} segment "
                f"durations; segment_durations has {len(durations)}", setting="segment_durations",
                code="segment-count")
        v0 = np.asarray(request.qd, float) if self.config.start_from_current else None
        traj = MultiCubicTrajectory(solve_multi_cubic(points, durations, v0), durations)
        jumps = np.degrees(traj.continuity())
        diag: dict[str, float] = {
            "ik_roundtrip_position_error_m": wp.ik_position_error_m,
            "ik_roundtrip_orientation_error_deg": wp.ik_orientation_error_deg,
        }
        for k, name in enumerate(names[1:-1]):
            for i, what in enumerate(("position_deg", "velocity_deg_s", "acceleration_deg_s2")):
                diag[f"continuity_{name}_{what}"] = float(jumps[k, i].max())
        for i, what in enumerate(("position_deg", "velocity_deg_s", "acceleration_deg_s2")):
            diag[f"continuity_max_{what}"] = float(jumps[:, i].max()) if len(jumps) else 0.0
        return Plan(traj, diag, points, waypoint_times=traj.breaks)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("multi-cubic", config=MultiCubicConfig, factory=MultiCubicPlanner)
