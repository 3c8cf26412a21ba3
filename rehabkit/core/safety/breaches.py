"""What a measured state broke, against the limits the safety layer checks (the robot's ranges with their margin, the
speed limits with their factor): the first limit, for a trip; and while a stop is under way, each limit it did not
hold, said once per rule and joint — the stop goes on, and the log says where it fell short."""

from __future__ import annotations

import numpy as np

from rehabkit.core.safety.limit_breach import LimitBreach, first_breach
from rehabkit.models.robot_model import JointLimits


class Breaches:
    """The limits broken by states against ``limits`` (joint ``names``; ``revolute`` ones said in degrees)."""

    RUN_STATE_FIELDS = ("_said",)  # (a snapshot's)

    def __init__(self, limits: JointLimits, names: list[str], revolute: np.ndarray):
        self.limits, self.names, self.revolute = limits, names, revolute
        self._said: set[tuple[str, str | None]] = set()

    def first(self, q: np.ndarray, qd: np.ndarray) -> LimitBreach | None:
        """The first limit ``q``, ``qd`` break: a position before a speed."""
        return first_breach(self.limits, self.names, q, qd, tol=0.0, revolute=self.revolute)

    def said(self, rule: str, joint: str | None) -> None:
        """A trip of ``rule`` at ``joint`` is in the log already (not said again during its stop)."""
        self._said.add((rule, joint))

    def during_stop(self, q: np.ndarray, qd: np.ndarray) -> LimitBreach | None:
        """A limit broken now, while a stop is under way, that was not said yet (then it is, from now on)."""
        lim = self.limits
        past, fast = (q < lim.lower) | (q > lim.upper), np.abs(qd) > lim.velocity
        if not (past.any() or fast.any()):
            return None
        for quantity, bad in (("position", past), ("velocity", fast)):
            for j in np.flatnonzero(bad):
                if (quantity, self.names[j]) in self._said:
                    continue
                self._said.add((quantity, self.names[j]))
                if quantity == "position":
                    value, limit = q[j], lim.lower[j] if q[j] < lim.lower[j] else lim.upper[j]
                else:
                    value, limit = abs(qd[j]), lim.velocity[j]
                return LimitBreach(quantity, self.names[j], float(value), float(limit), revolute=bool(self.revolute[j]))
        return None
