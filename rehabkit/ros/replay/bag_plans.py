"""How a session's targets were planned, read from its bag: which were one plan, and when each plan's last movement
ended — what a replay must know to plan them again as they were.

A target shown while the robot was still moving towards the one before is a via point of the plan under way (a
multi-cubic plan through via points passes them at speed), so it and the targets before it since the robot last
stood are one plan: replayed as one replan through them, each segment the time until the next was shown. A target
shown while the robot stood begins a new plan. "Moving" is read from the joints' reference where the bag has it
(rehabkit's bags: ``/reference/joint_states``; a plan from rest starts at zero speed, exactly), else from the
measured joints (their speed over a short window around the target's time: a robot lags its reference, so a plan
that ended as the next began may still be seen moving; an estimate). A plan's last movement ends where the
reference stopped changing; without a reference, or where it had not stopped before the next plan began (or the
session ended), it is given the time until then.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rehabkit.ros.replay.session_bag import SessionBag, ShownTarget

MOVING = 0.1  # still moving: the joints' speed when a target was shown above this fraction of the movement's before
SETTLE_S = 0.05  # the measured joints: their least speed within this of a target's time is taken (they lag)
STILL = 1e-12  # a reference that changes by no more than this between samples [rad, m] stands still


@dataclass(frozen=True)
class ShownPlan:
    """Targets ``first`` to ``last`` (indices into the shown targets, both in) planned as one from ``t`` [s]: each
    segment's duration [s] (``durations``, one per target: the time until the next was shown, the last's until the
    plan ended) and whether that end was read from the reference (``end_known``; else: until the next plan began,
    or the session's end)."""

    first: int
    last: int
    t: float
    durations: list[float]
    end_known: bool


def _speed(t: np.ndarray, q: np.ndarray, qd: np.ndarray | None) -> np.ndarray:
    """The joints' speed (the norm of their velocities, SI: rad/s and m/s together) at the samples ``t``: the
    velocities given, else the positions' rate of change."""
    if qd is None:
        qd = np.gradient(q, t, axis=0) if len(t) > 1 else np.zeros_like(q)
    return np.linalg.norm(qd, axis=1)


def _window(t: np.ndarray, a: float, b: float) -> slice:
    """The samples of ``t`` from ``a`` to ``b`` (at least the one nearest ``a``)."""
    i = int(np.searchsorted(t, a - 1e-9))
    return slice(min(i, len(t) - 1), max(int(np.searchsorted(t, b + 1e-9, side="right")), i + 1))


def _moving(t: np.ndarray, speed: np.ndarray, before: float, at: float, settle: float, floor: float) -> bool:
    """Whether the joints were still moving when a target was shown at ``at``: their least speed within
    ``settle`` of it above :data:`MOVING` times the movement's fastest since ``before`` (itself above ``floor``)."""
    peak = float(speed[_window(t, before, at)].max())
    least = float(speed[_window(t, at - settle, at + settle)].min())
    return peak > floor and least > MOVING * peak


def _stopped(t: np.ndarray, q: np.ndarray, a: float, b: float) -> float | None:
    """When the reference stopped changing from ``a`` until ``b`` [s] (``b`` itself not counted: the next plan's
    first sample): the first sample of its last still stretch; None where it changed up to ``b`` (still moving, or
    a plan that ended as the next began), did not change at all, or ends before ``b``."""
    k0, k1 = int(np.searchsorted(t, a - 1e-9)), int(np.searchsorted(t, b - 1e-9))
    if k1 - k0 < 2 or t[k1 - 1] < b - 1.5 * float(np.median(np.diff(t))):
        return None
    changed = np.flatnonzero(np.abs(np.diff(q[k0:k1], axis=0)).max(axis=1) > STILL)
    if not len(changed) or k0 + changed[-1] + 1 >= k1 - 1:
        return None
    return float(t[k0 + changed[-1] + 1])


def session_plans(bag: SessionBag, shown: list[ShownTarget]) -> list[ShownPlan]:
    """The shown targets as the plans they were (see the module): from the reference where the bag has one, else
    from the measured joints."""
    if not shown:
        return []
    ref = bag.reference
    if ref is not None:
        t, q = ref.t, ref.values
        speed = _speed(t, q, None if bag.reference_velocity is None else bag.reference_velocity.values)
        settle, floor = 0.0, STILL
    else:
        t, q = bag.joints.t, bag.joints.values
        speed = _speed(t, q, None if bag.velocity is None else bag.velocity.values)
        settle, floor = SETTLE_S, MOVING * float(speed.max())
    starts = [0] + [i for i in range(1, len(shown))
                    if not _moving(t, speed, shown[i - 1].t, shown[i].t, settle, floor)]
    plans = []
    for n, first in enumerate(starts):
        last = starts[n + 1] - 1 if n + 1 < len(starts) else len(shown) - 1
        until = shown[last + 1].t if last + 1 < len(shown) else bag.duration_s
        end = _stopped(t, q, shown[last].t, until) if ref is not None else None
        times = [s.t for s in shown[first:last + 1]] + [end if end is not None else until]
        plans.append(ShownPlan(first, last, shown[first].t, [max(b - a, 1e-3) for a, b in zip(times, times[1:])],
                               end is not None))
    return plans
