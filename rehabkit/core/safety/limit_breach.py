"""A joint limit broken: where, by how much, in the joint's own unit — found in a state, a row of states, or a whole
plan sampled every ``CHECK_DT`` (the safety layer's check and the plan gate's, and validate's)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from rehabkit.models.robot_model import JointLimits

Quantity = Literal["position", "velocity", "torque"]


@dataclass(frozen=True)
class LimitBreach:
    """A joint beyond one of its limits.

    Attributes:
        quantity: ``position``, ``velocity`` or ``torque``.
        joint: The joint's name.
        value: What it was (SI units; a speed or torque as a magnitude when compared with one).
        limit: The limit it broke (the bound on the side it crossed).
        at_s: When, in seconds from the start of what was checked (a plan), if known.
        revolute: Report in degrees and N·m rather than metres and N (a prismatic joint's).
    """

    quantity: Quantity
    joint: str
    value: float
    limit: float
    at_s: float | None = None
    revolute: bool = True

    def describe(self) -> str:
        """``elbow beyond its position limit at t+0.250s (131.2°, limit 120.0°)``: the one wording of a breach."""
        what = self.quantity
        if self.quantity == "torque":  # (a prismatic joint's is a force)
            v, lim, unit = self.value, self.limit, " N·m" if self.revolute else " N"
            what = "torque" if self.revolute else "force"
        elif self.revolute:
            v, lim = math.degrees(self.value), math.degrees(self.limit)
            unit = "°" if self.quantity == "position" else " °/s"
        else:
            v, lim, unit = self.value, self.limit, " m" if self.quantity == "position" else " m/s"
        when = f" at t+{self.at_s:.3f}s" if self.at_s is not None else ""
        first = 1 if self.revolute or self.quantity == "torque" else 3  # (metres to the millimetre: 0.12 was "0.1")
        d = next((d for d in range(first, 7) if f"{abs(v):.{d}f}" != f"{abs(lim):.{d}f}"), 6)  # (never "3, limit 3")
        return f"{self.joint} beyond its {what} limit{when} ({v:.{d}f}{unit}, limit {lim:.{d}f}{unit})"


def first_breach(limits: JointLimits, names: list[str], q: np.ndarray, qd: np.ndarray | None = None,
                 times: np.ndarray | None = None, tol: float | np.ndarray = 1e-9,
                 revolute: np.ndarray | None = None) -> LimitBreach | None:
    """The first sample of ``q`` (n, dof) outside the range or of ``qd`` beyond the speed limit, if any.

    Positions are checked before speeds (a sample breaking both reports its position); ``tol`` is how far past its
    range a joint may be (per joint, or one for all). ``revolute`` says which joints turn (reported in degrees; the
    others in metres); default all.
    """
    def turns(j: int) -> bool:
        return True if revolute is None else bool(revolute[j])

    q = np.atleast_2d(q)
    bad_q = (q < limits.lower - tol) | (q > limits.upper + tol)
    if bad_q.any():
        k, j = np.argwhere(bad_q)[0]
        limit = limits.lower[j] if q[k, j] < limits.lower[j] else limits.upper[j]
        return LimitBreach("position", names[j], float(q[k, j]), float(limit),
                           None if times is None else float(times[k]), turns(j))
    if qd is not None:
        qd = np.atleast_2d(qd)
        bad_v = np.abs(qd) > limits.velocity
        if bad_v.any():
            k, j = np.argwhere(bad_v)[0]
            return LimitBreach("velocity", names[j], float(abs(qd[k, j])), float(limits.velocity[j]),
                               None if times is None else float(times[k]), turns(j))
    return None


def outside(q: np.ndarray, limits: JointLimits, tol: float = 1e-9) -> list[int]:
    """Indices of joints of ``q`` outside ``limits``."""
    return [j for j in range(len(q)) if q[j] < limits.lower[j] - tol or q[j] > limits.upper[j] + tol]


CHECK_DT = 0.005  # plans are checked at this resolution [s]


def plan_breach(plan, model, within: float | None = None) -> LimitBreach | None:
    """The first joint limit of ``model`` a joint-space plan (:class:`~rehabkit.core.kinds.interfaces.Plan`) breaks,
    sampled every ``CHECK_DT`` — over the first ``within`` seconds where only they can run (the run ends: a plan of
    12,000 s, segment durations in milliseconds by mistake, took 2.8 s to check in a 2-s run)."""
    span = plan.trajectory.duration if within is None else min(plan.trajectory.duration, max(within, 0.0))
    ts = np.arange(0.0, span + 1e-9, CHECK_DT)
    qs, qds, _ = plan.trajectory.sample(ts)
    # a plan starts where the robot is: a joint resting a hair past its range (a simulated limit gives a little, a
    # target exactly at the limit) may stay there, not go further
    lim = model.limits
    start = np.maximum(np.maximum(lim.lower - qs[0], qs[0] - lim.upper), 0.0)
    return first_breach(lim, model.joint_names, qs, qds, ts, tol=np.maximum(1e-9, start + 1e-12),
                        revolute=model.revolute)
