"""Time laws for geometric joint paths: each straight segment of a polyline run rest to rest.

A quintic s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ on each segment keeps the motion exactly on the polyline a planner checked
for collisions (a blend through the corners would leave it), with zero velocity and acceleration at every
vertex. Its peaks are 1.875 Δ/T in velocity and 10/√3 · Δ/T² in acceleration, which set each segment's duration
from the joints' limits.
"""

from __future__ import annotations

import numpy as np

from rehabkit.models.time_laws import PEAK_ACCELERATION, PEAK_VELOCITY, quintic


def rest_to_rest_durations(points: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                           shortest_s: float = 0.05) -> np.ndarray:
    """Each segment's duration [s]: the least that keeps every joint within ``velocity`` and ``acceleration``."""
    delta = np.abs(np.diff(np.asarray(points, float), axis=0))
    by_speed = PEAK_VELOCITY * delta / velocity
    by_accel = np.sqrt(PEAK_ACCELERATION * delta / acceleration)
    return np.maximum(np.maximum(by_speed, by_accel).max(axis=1), shortest_s)


class RestToRestPath:
    """A joint polyline timed segment by segment (see the module); ``sample`` is vectorised over times."""

    def __init__(self, points: np.ndarray, durations: np.ndarray):
        self.points = np.asarray(points, float)
        self.durations = np.asarray(durations, float)
        self.breaks = np.concatenate([[0.0], np.cumsum(self.durations)])
        self.duration = float(self.breaks[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        if not len(self.durations):  # one point (the goal is where the path starts): held there
            held = np.broadcast_to(self.points[0], (len(t), self.points.shape[1])).copy()
            return held, np.zeros_like(held), np.zeros_like(held)
        seg = np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, len(self.durations) - 1)
        T = self.durations[seg][:, None]
        tau = (t - self.breaks[seg])[:, None] / T
        s, sd, sdd = quintic(tau)
        sd, sdd = sd / T, sdd / T**2
        delta = self.points[seg + 1] - self.points[seg]
        return self.points[seg] + s * delta, sd * delta, sdd * delta
