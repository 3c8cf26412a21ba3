"""The bridge's own limit check: a backstop to the host's safety layer, a margin wider than it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class BridgeLimits:
    """Where the bridge stops the robot on its own: the run's joint limits widened by a margin, so that the
    host's safety layer (0.5° beyond the range by default) acts first and this only when it did not."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    margin: float = math.radians(2.0)  # beyond the range [rad, or m for a sliding joint]
    speed_factor: float = 1.25  # beyond the speed limit

    def __post_init__(self) -> None:
        self._low, self._high = self.lower - self.margin, self.upper + self.margin
        self._fast = self.speed_factor * self.velocity

    def breach(self, q: np.ndarray, qd: np.ndarray) -> str | None:
        """Why the state is beyond the limits, or None."""
        out = (q < self._low) | (q > self._high)
        fast = np.abs(qd) > self._fast
        if not (out | fast).any():  # every tick: one test
            return None
        if out.any():
            k = int(np.argmax(out))
            side = "lower" if q[k] < self.lower[k] else "upper"
            return f"joint {k} beyond its {side} limit: {q[k]:.4f} (limit {getattr(self, side)[k]:.4f})"
        k = int(np.argmax(fast))
        return f"joint {k} too fast: {qd[k]:.3f} (limit {self.velocity[k]:.3f})"
