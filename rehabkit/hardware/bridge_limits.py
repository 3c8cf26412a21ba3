"""The bridge's own limit check: a backstop to the host's safety layer, a margin wider than it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MARGIN_DEG = 2.0  # how far beyond a revolute joint's range the bridge trips (the host's, by default, at 0.5°)
MARGIN_M = 0.01  # ... and beyond a prismatic joint's (the host's at 5 mm)


@dataclass
class BridgeLimits:
    """Where the bridge stops the robot on its own: the run's joint limits widened by a margin, so that the
    host's safety layer (0.5° or 5 mm beyond the range by default) acts first and this only when it did not.

    Attributes:
        lower, upper, velocity: The run's limits per joint (SI: rad, or m for a prismatic joint; rad/s, or m/s).
        margin: How far beyond a revolute joint's range it trips [rad].
        speed_factor: How far beyond the speed limit it trips (a multiple of it).
        margin_m: How far beyond a prismatic joint's range it trips [m].
        revolute: Which joints turn (``margin``), the others slide (``margin_m``); None: all turn.
    """

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    margin: float = math.radians(MARGIN_DEG)
    speed_factor: float = 1.25
    margin_m: float = MARGIN_M
    revolute: np.ndarray | None = None

    def __post_init__(self) -> None:
        wide = self.margin if self.revolute is None else np.where(self.revolute, self.margin, self.margin_m)
        self._low, self._high = self.lower - wide, self.upper + wide
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
