"""How the robot stops after a trip: the stop categories of IEC 60204-1, and what a stop took.

- **0**: torque off at once and the robot's brakes on (an uncontrolled stop: without brakes it coasts, or falls).
- **1**: a controlled stop — every joint's speed brought to zero along a ramp whose deceleration is bounded
  (``safety.stop_decel_deg_s2``; a prismatic joint's ``stop_decel_m_s2``; by default half what each drive can
  give its joint), all joints reaching zero together — then torque off and the robot's brakes (if it has any) on.
- **2**: the same controlled stop, then the posture held (PD to it plus gravity compensation).

The ramp is a reference the hold gains track with gravity compensation, within the effort limits. What
a stop took — time from the trigger to standstill, the joints' and the hand's travel meanwhile — is
measured from the run's trace (:func:`stop_figures`), on every backend alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rehabkit.core.safety.event import SafetyEvent
from rehabkit.core.scenario.safety import STOP_RULES

STANDSTILL_DEG_S = 1.0  # every joint slower than this ...
STANDSTILL_FOR_S = 0.05  # ... for this long: at standstill
WORDS = {0: "torque off (category 0)", 1: "controlled stop, then torque off (category 1)",
         2: "controlled stop, then held (category 2)"}


STOP_DELAYS = 5  # a controlled stop lasts at least this many of the backend's loop delays


@dataclass
class ControlledStop:
    """The deceleration ramp of a category 1 or 2 stop, from the state at the trip."""

    category: int
    t0: float
    q0: np.ndarray
    v0: np.ndarray
    duration: float  # until every joint's reference speed is zero [s]

    feedforward: np.ndarray | None = None  # M(q₀) q̈: the torque of the ramp's constant deceleration

    @classmethod
    def start(cls, category: int, t: float, q: np.ndarray, qd: np.ndarray | None, decel: np.ndarray | None,
              effort: np.ndarray, robot, dt: float, delay: float = 0.0) -> ControlledStop:
        """The ramp from the state at the trip; ``decel`` [rad/s², or m/s²] per joint, or None (NaN for a joint):
        half what each drive can give its joint at this posture (effort / inertia), the quickest stop that keeps a
        margin for gravity. With the backend's loop ``delay`` the ramp lasts at least ``STOP_DELAYS`` of it: its
        decelerating torque, acting that late, would else still push a joint that has stopped (a stop of two cycles
        on a bus overshoots backwards)."""
        v0 = np.zeros_like(q) if qd is None else np.where(np.isfinite(qd), qd, 0.0)
        inertia = mass_matrix(robot, q)
        if decel is None or np.isnan(decel).any():  # (NaN: a joint whose kind has no bound set)
            own = 0.5 * effort / np.diag(inertia) if inertia is not None else np.full(len(q), np.radians(360.0))
            decel = own if decel is None else np.where(np.isnan(decel), own, decel)
        duration = max(float(np.max(np.abs(v0) / decel)) if len(v0) else 0.0, dt, STOP_DELAYS * delay)
        stop = cls(category, t, q.copy(), v0, duration)
        if inertia is not None:
            stop.feedforward = inertia @ (-v0 / duration)  # (the posture changes little over a stop)
        return stop

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and speed of the ramp at ``t`` (held at its end afterwards)."""
        s = min(max(t - self.t0, 0.0), self.duration)
        return self.q0 + self.v0 * (s - s * s / (2 * self.duration)), self.v0 * (1.0 - s / self.duration)

    def over(self, t: float) -> bool:
        return t - self.t0 >= self.duration

    @property
    def end(self) -> np.ndarray:
        return self.q0 + self.v0 * self.duration / 2


def mass_matrix(robot, q: np.ndarray) -> np.ndarray | None:
    """The joint-space inertia at ``q`` (Pinocchio), or None for a robot without a dynamic model."""
    try:
        import pinocchio as pin

        model = robot.pin_model
        return pin.crba(model, model.createData(), np.asarray(q, float))
    except Exception:  # noqa: BLE001 (no dynamic model: the gains alone track the ramp)
        return None


def joint_inertia(robot, q: np.ndarray) -> np.ndarray | None:
    """Each joint's inertia at ``q`` as its own torque meets it, the other joints free: 1 / (M⁻¹)ⱼⱼ with its rotor's
    (armature) on the diagonal [kg·m²; kg for a sliding joint] — a wrist on a moving arm is lighter than Mⱼⱼ says —,
    or None without a dynamic model."""
    inertia = mass_matrix(robot, q)
    if inertia is None:
        return None
    try:
        rotor = np.asarray(robot.pin_model.armature, float)[: len(q)]
    except Exception:  # noqa: BLE001 (no rotor inertia known)
        rotor = np.zeros(len(q))
    return 1.0 / np.diag(np.linalg.inv(inertia + np.diag(rotor)))


def stable_gains(kp: float | np.ndarray, kd: float | np.ndarray, inertia: np.ndarray | None,
                 dt: float, damping: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """PD gains per joint that a control period ``dt`` can apply stably: damping at most half the inertia / dt (a
    joint's speed decays without changing sign within a period, with a margin for the state's delay), the stiffness
    then at most critical for it (kd² / 4 m). A light joint (a small wrist) cannot take a heavy one's gains: at
    kd·dt/m above 2 the hold oscillates and grows. A joint's own viscous ``damping`` d weighs as d·dt of inertia
    over a period (the speed it takes away within one): a light wrist in a heavily damped drive bears stiffer
    gains than its inertia alone."""
    kp, kd = np.asarray(kp, float), np.asarray(kd, float)
    if inertia is None:
        return kp, kd
    if damping is not None:
        inertia = inertia + np.asarray(damping, float) * dt
    cap = 0.5 * inertia / dt
    capped = kd > cap
    kd_eff = np.where(capped, cap, kd)
    return np.where(capped, np.minimum(kp, kd_eff**2 / (4 * inertia)), kp), kd_eff


def stop_figures(t: np.ndarray, q: np.ndarray, qd: np.ndarray, hand: np.ndarray | None, trip_t: float,
                 revolute: np.ndarray) -> dict[str, float]:
    """What a stop took, from the trace: the time from the trigger to standstill [s] (every revolute joint below
    1°/s and every prismatic one below 1 mm/s for 50 ms; up to the end of the record when it never came to rest,
    ``stop_time_s`` then NaN), and meanwhile each kind of joint's largest travel and peak speed in its own unit —
    ``stop_distance_deg`` and ``stop_peak_speed_deg_s`` over the revolute joints, ``stop_joint_travel_m`` and
    ``stop_joint_peak_speed_m_s`` over the prismatic ones (a kind the robot lacks has none) — and the hand's path
    ``stop_distance_m`` [m]."""
    k0 = int(np.searchsorted(t, trip_t - 1e-12))
    if k0 >= len(t):
        return {}
    revolute = np.asarray(revolute, bool)
    # (the standstill test in deg/s and mm/s alike; the figures in each joint's own unit below)
    speed = np.abs(qd[k0:]) * np.where(revolute, np.degrees(1.0), 1e3)
    still = (speed < STANDSTILL_DEG_S).all(axis=1)
    dt = float(t[1] - t[0]) if len(t) > 1 else 1e-3
    need = max(1, math.ceil(STANDSTILL_FOR_S / dt - 1e-9))
    # the first step of a run of `need` still steps
    runs = np.convolve(still.astype(int), np.ones(need, int), mode="valid") == need
    hits = np.flatnonzero(runs)
    k1 = k0 + int(hits[0]) if len(hits) else len(t) - 1
    travel = np.abs(q[k0 : k1 + 1] - q[k0]).max(axis=0)  # [rad, or m]
    peak = np.abs(qd[k0:]).max(axis=0)  # [rad/s, or m/s]
    path = float(np.linalg.norm(np.diff(hand[k0 : k1 + 1], axis=0), axis=1).sum()) if hand is not None else math.nan
    out = {"stop_time_s": float(t[k1] - trip_t) if len(hits) else math.nan, "stop_distance_m": path}
    if revolute.any():
        out.update(stop_distance_deg=float(np.degrees(travel[revolute].max())),
                   stop_peak_speed_deg_s=float(np.degrees(peak[revolute].max())))
    if not revolute.all():
        out.update(stop_joint_travel_m=float(travel[~revolute].max()),
                   stop_joint_peak_speed_m_s=float(peak[~revolute].max()))
    return out


def stop_decel(config, revolute: np.ndarray) -> np.ndarray | None:
    """The envelope's (``config``, a ``SafetyConfig``) deceleration bound per joint [rad/s², or m/s²]:
    ``stop_decel_deg_s2`` on a revolute joint, ``stop_decel_m_s2`` on a prismatic one; NaN where its kind's is not
    set, None where neither is (each drive's own: :meth:`ControlledStop.start`)."""
    turn, slide = config.stop_decel_deg_s2, config.stop_decel_m_s2
    if turn is None and slide is None:
        return None
    return np.where(revolute, math.nan if turn is None else math.radians(turn), math.nan if slide is None else slide)


def stop_categories(robot, config) -> dict[str, int]:
    """The stop category of each rule: the envelope's, else 2 for a robot that holds its posture and 0 for one whose
    safe stop is zero torque."""
    default = 2 if robot.safe_stop == "hold" else 0
    return {r: config.category_of(r, default) for r in STOP_RULES}


class Stopping:
    """How :class:`~rehabkit.core.safety.layer.SafetyLayer` stops the robot once it has tripped: the category each
    rule gets, the controlled stop's ramp, the hold, the torque going off; ``note`` keeps its interventions."""

    RUN_STATE_FIELDS = ("category", "ramp", "limp", "hold_q")  # (what a stop under way changes: a snapshot's)

    def __init__(self, robot, config, lo: np.ndarray, hi: np.ndarray, gravity, dt: float, note,
                 gain_dt: float | None = None):
        self.config, self.lo, self.hi, self.gravity, self.dt, self.note = config, lo, hi, gravity, dt, note
        self.gain_dt = gain_dt or dt  # (the period and the backend's loop delay: what the hold's gains must bear)
        self.robot, self.effort, self.zero = robot, robot.limits.effort, np.zeros(robot.dof)
        self.by_rule = stop_categories(robot, config)
        self.decel = stop_decel(config, robot.revolute)
        self.category: int | None = None  # the stop under way's
        self.ramp: ControlledStop | None = None
        self.limp = False  # category 1 at standstill: the torque is off
        self.hold_q: np.ndarray | None = None
        self._gains: tuple[np.ndarray, np.ndarray] | None = None  # the hold's, per joint (stable_gains), made once

    def category_of(self, rule: str) -> int:
        return self.by_rule.get(rule, self.by_rule["default"])

    def begin(self, t: float, category: int, q: np.ndarray, qd: np.ndarray | None) -> None:
        """The stop starts at ``t`` from state ``(q, qd)`` in ``category``."""
        hold = np.where(np.isfinite(q), q, 0.0)
        self.hold_q = np.clip(hold, self.lo, self.hi)
        self.category = category
        if category:
            self.ramp = ControlledStop.start(category, t, hold, qd, self.decel, self.effort, self.robot, self.dt,
                                             self.gain_dt - self.dt)

    @property
    def torque_off(self) -> bool:
        """The torque has gone off (category 0, or 1 once stopped)."""
        return self.category == 0 or self.limp

    def braked(self, t: float, engaged: bool) -> None:
        """Record that the torque went off, and whether brakes hold the robot."""
        cause = "torque off; " + ("holding brakes engaged" if engaged else
                                  "no brakes: the robot is free to move (gravity, the person)")
        self.note(SafetyEvent(t, "brakes", None, None, None, f"t={t:.3f}s: {cause}", {"engaged": engaged},
                              cause=cause))

    def gains(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The hold's stiffness and damping per joint: the envelope's, within what a control period can apply stably
        to each joint's inertia (taken where the robot first needs holding)."""
        if self._gains is None:
            inertia = joint_inertia(self.robot, np.where(np.isfinite(q), q, 0.0))
            self._gains = stable_gains(self.config.hold_kp, self.config.hold_kd, inertia, self.gain_dt,
                                       self.robot.dissipation.damping)
        return self._gains

    def hold_torque(self, posture: np.ndarray, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """PD to ``posture`` with gravity compensation, within the effort limits."""
        kp, kd = self.gains(q)
        tau = kp * (posture - q) - kd * qd
        if self.gravity is not None:
            tau += self.gravity(q)
        return np.clip(tau, -self.effort, self.effort)

    def target(self, t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where a joint on a position target goes at ``t`` while stopping (after :meth:`torque` took the stop that
        far): along the ramp, then the held posture; with the torque off, where it is."""
        if self.category == 0 or self.limp:
            return np.where(np.isfinite(q), q, self.hold_q), np.zeros(len(q))
        if self.ramp is not None:
            return self.ramp.reference(t)
        return self.hold_q, np.zeros(len(q))

    def torque(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """What to send at ``t`` while stopping: along the ramp, then held or off."""
        if self.category == 0 or self.limp:
            return self.zero.copy()
        q = np.where(np.isfinite(q), q, self.hold_q)
        qd = np.where(np.isfinite(qd), qd, 0.0)
        stop = self.ramp
        if stop is not None:
            if not stop.over(t):  # on the deceleration ramp
                q_r, qd_r = stop.reference(t)
                kp, kd = self.gains(q)
                tau = kp * (q_r - q) + kd * (qd_r - qd)
                if stop.feedforward is not None:  # the ramp's deceleration, and what the joints lose at its speed
                    tau += stop.feedforward + self.robot.dissipation.torque(qd_r)
                if self.gravity is not None:
                    tau += self.gravity(q)
                return np.clip(tau, -self.effort, self.effort)
            self.ramp = None
            if stop.category == 1:
                self.limp = True
                return self.zero.copy()
            self.hold_q = np.clip(stop.end, self.lo, self.hi)
        return self.hold_torque(self.hold_q, q, qd)
