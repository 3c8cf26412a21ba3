"""The safety layer between every controller and every backend.

Each control step it checks the measured state and the commanded torques
against the robot's limits. A non-finite value, a joint outside its range or
faster than its speed limit trips a latched stop: from then on the controller is
ignored and the robot is held where it was (``hold``: PD to the trip posture
with gravity compensation, within effort limits) or left limp
(``zero-torque``), as the robot model says. Torques beyond the effort limit
are clipped and counted, or trip the stop if the scenario asks.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from rehabkit.core.interfaces import StrictModel
from rehabkit.models.robot_model import RobotModel


class SafetyConfig(StrictModel):
    """Safety-layer settings of a scenario."""

    position_margin_deg: float = Field(0.5, ge=0, description="tolerance beyond a joint's range before tripping")
    velocity_factor: float = Field(1.0, gt=0, description="trip above this multiple of the velocity limit")
    torque_policy: Literal["clip", "stop"] = "clip"
    hold_kp: float = Field(60.0, gt=0, description="hold stiffness after a trip [N·m/rad]")
    hold_kd: float = Field(6.0, gt=0, description="hold damping after a trip [N·m·s/rad]")
    stop_after_s: float = Field(0.5, ge=0, description="keep simulating this long after a trip, then end the run")


@dataclass
class SafetyEvent:
    """Why the safety layer acted."""

    t: float
    rule: str
    joint: str | None
    value: float | None
    limit: float | None
    message: str

    def as_dict(self) -> dict:
        return asdict(self)


class SafetyLayer:
    """Checks every command; see the module docstring for the rules."""

    def __init__(self, robot: RobotModel, config: SafetyConfig, gravity=None):
        """``gravity(q)`` gives the holding torques of a trip (``None``: PD only)."""
        lim = robot.limits
        margin = math.radians(config.position_margin_deg)
        self.names = robot.joint_names
        self.lo, self.hi = lim.lower - margin, lim.upper + margin
        self.vmax = lim.velocity * config.velocity_factor
        self.effort = lim.effort
        self.config = config
        self.mode = robot.safe_stop
        self.events: list[SafetyEvent] = []
        self.tripped_at: float | None = None
        self.saturated_steps = 0
        self._hold_q: np.ndarray | None = None
        self._gravity = gravity
        self._zero = np.zeros(robot.dof)
        # the fast path tests |[q, qd, tau] - centre| <= bound in one go; NaN fails it too
        n = robot.dof
        self._n = n
        self._centre = np.concatenate([(self.lo + self.hi) / 2, np.zeros(2 * n)])
        self._bound = np.concatenate([(self.hi - self.lo) / 2, self.vmax, self.effort])
        self._buf = np.empty(3 * n)
        self._ok = np.empty(3 * n, dtype=bool)

    @property
    def tripped(self) -> bool:
        return self.tripped_at is not None

    def filter(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The torque to send: ``tau`` if safe (possibly clipped), else the stop torque."""
        return self.check_row(t, np.concatenate((q, qd, tau)))

    def check_row(self, t: float, row: np.ndarray) -> np.ndarray:
        """Check a packed ``[q, qd, tau]`` row; its torque part is overwritten with what to send.

        The runner records rows straight into its trace, so checking costs no copy.
        """
        n = self._n
        if self.tripped_at is None:
            b = np.subtract(row, self._centre, out=self._buf)
            np.abs(b, out=b)
            if np.less_equal(b, self._bound, out=self._ok).all():
                return row[2 * n :]
        q, qd, tau = row[:n], row[n : 2 * n], row[2 * n :]
        if self.tripped_at is None:
            # slow path: find out what went wrong
            if (
                math.isfinite(tau.sum() + q.sum() + qd.sum())
                and not (q < self.lo).any()
                and not (q > self.hi).any()
                and not (np.abs(qd) > self.vmax).any()
            ):
                over = np.abs(tau) > self.effort
                if not over.any():
                    return tau
                if self.config.torque_policy == "clip":
                    self.saturated_steps += 1
                    return np.clip(tau, -self.effort, self.effort, out=tau)
                j = int(np.argmax(over))
                self._trip(
                    t, q, "torque", j, float(tau[j]), float(self.effort[j]), "commanded torque beyond effort limit"
                )
            else:
                self._diagnose(t, q, qd, tau)
        tau[:] = self._stop_torque(q, qd)
        return tau

    def trip(self, t: float, q: np.ndarray, rule: str, message: str) -> None:
        """Trip from outside (a rejected plan, an external e-stop)."""
        self._trip(t, q, rule, None, None, None, message)

    def _diagnose(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> None:
        for name, arr in (("state position", q), ("state velocity", qd), ("command torque", tau)):
            bad = ~np.isfinite(arr)
            if bad.any():
                j = int(np.argmax(bad))
                self._trip(t, q, "non-finite", j, None, None, f"non-finite {name} ({arr[j]})")
                return
        for j in range(len(q)):
            if q[j] < self.lo[j] or q[j] > self.hi[j]:
                limit = self.lo[j] if q[j] < self.lo[j] else self.hi[j]
                self._trip(t, q, "position", j, float(q[j]), float(limit), "joint outside its range")
                return
        j = int(np.argmax(np.abs(qd) / self.vmax))
        self._trip(t, q, "velocity", j, float(qd[j]), float(self.vmax[j]), "joint faster than its limit")

    def _trip(self, t, q, rule, joint, value, limit, message) -> None:
        name = self.names[joint] if joint is not None else None
        text = f"t={t:.3f}s: {message}" + (f": {name} = {value:.4g} (limit {limit:.4g})" if value is not None else "")
        text += f"; robot {'held' if self.mode == 'hold' else 'set to zero torque'}"
        self.events.append(SafetyEvent(t, rule, name, value, limit, text))
        self.tripped_at = t
        hold = np.where(np.isfinite(q), q, 0.0)
        self._hold_q = np.clip(hold, self.lo, self.hi)

    def _stop_torque(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        if self.mode == "zero-torque":
            return self._zero.copy()
        q = np.where(np.isfinite(q), q, self._hold_q)
        qd = np.where(np.isfinite(qd), qd, 0.0)
        tau = self.config.hold_kp * (self._hold_q - q) - self.config.hold_kd * qd
        if self._gravity is not None:
            tau += self._gravity(q)
        return np.clip(tau, -self.effort, self.effort)
