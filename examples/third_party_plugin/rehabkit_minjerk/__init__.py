"""A third-party rehabkit planner: minimum-jerk motion between via points.

Each segment is the quintic that minimises squared jerk from rest to rest
(Flash & Hogan's model of unconstrained human reaching), so the arm pauses at
every via point — the usual choice for point-to-point therapy exercises.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import (
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


class MinJerkConfig(StrictModel):
    """Durations of the rest-to-rest segments."""

    segment_durations: list[float] = Field(min_length=1, description="[s], one per segment")


class MinJerkTrajectory:
    """Rest-to-rest quintic segments through joint via points."""

    def __init__(self, points: np.ndarray, durations: np.ndarray):
        self.points, self.durations = points, durations
        self.breaks = np.concatenate([[0.0], np.cumsum(durations)])
        self.duration = float(self.breaks[-1])

    def sample(self, t):
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        seg = np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, len(self.durations) - 1)
        T = self.durations[seg][:, None]
        s = ((t - self.breaks[seg])[:, None]) / T
        delta = self.points[seg + 1] - self.points[seg]
        pos = 10 * s**3 - 15 * s**4 + 6 * s**5
        vel = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
        acc = (60 * s - 180 * s**2 + 120 * s**3) / T**2
        return self.points[seg] + delta * pos, delta * vel, delta * acc


class MinJerkPlanner(Planner):
    """Minimum-jerk (quintic) rest-to-rest segments through the task's via points."""

    # every figure the plan reports, declared: a scenario's expect: on any other name is refused by validate
    metrics = (
        Metric("ik_roundtrip_position_error_m", "m", description="largest hand error of the via points' IK"),
        Metric("min_jerk_peak_speed_rad_s", "rad/s", description="fastest joint speed of the plan"),
    )

    def __init__(self, config: MinJerkConfig, context=None):
        self.durations = np.asarray(config.segment_durations, dtype=float)
        if np.any(self.durations <= 0):
            raise SettingError("segment_durations", "every segment duration must be > 0")

    def plan(self, request: PlanRequest) -> Plan:
        wp = joint_waypoints(request.targets, request.robot, request.q)
        if len(self.durations) != len(wp.q) - 1:
            raise PlanningError(f"min-jerk: {len(wp.q)} via points need {len(wp.q) - 1} segment durations, "
                                f"got {len(self.durations)}", setting="segment_durations")
        peak = np.max(np.abs(np.diff(wp.q, axis=0)) * 1.875 / self.durations[:, None])  # 15/8 Δ/T
        return Plan(MinJerkTrajectory(wp.q, self.durations),
                    {"ik_roundtrip_position_error_m": wp.ik_position_error_m, "min_jerk_peak_speed_rad_s": peak},
                    wp.q)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("min-jerk", config=MinJerkConfig, factory=MinJerkPlanner)
