"""The safety layer between every controller and every backend: the scenario's ``safety:`` envelope.

Each control step it checks the measured state and the commanded torques against the effective limits (the
robot's, narrowed by the patient's profile and the envelope's per-joint limits). A non-finite value, a joint outside
its range or faster than its speed limit, the hand outside the keep-in box or an interaction force above its limit
trips a latched stop: from then on the controller is ignored and the robot stopped in the category the envelope sets
for the rule (:mod:`rehabkit.core.safety.stopping`; by default 2, or 0 for a robot whose ``safe_stop`` is
``zero-torque``). The interaction force may instead get a force-limiting reaction (``safety.reactions``: yield or
retreat, :mod:`rehabkit.core.safety.compliance`), under which the other rules still hold. Torques beyond the effort
limit are clipped (each episode an intervention) or trip the stop if the scenario asks. A ramp-in blends from holding
the start posture to the controller's torque, a ramp-out back to holding the posture where it began.

The layer runs on the host for every backend: a breach is the same event in simulation and over a hardware link.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rehabkit.core.kinds.run_state import RunState
from rehabkit.core.safety.breaches import Breaches
from rehabkit.core.safety.compliance import Compliance
from rehabkit.core.safety.event import Clipping, SafetyEvent
from rehabkit.core.safety.keep_in import KeepIn, world_box
from rehabkit.core.safety.limit_breach import LimitBreach
from rehabkit.core.safety.ramps import Ramps
from rehabkit.core.safety.stopping import WORDS, Stopping, stop_categories
from rehabkit.core.scenario.safety import SafetyConfig
from rehabkit.models.robot_model import JointLimits, RobotModel

# numpy's own count_nonzero: the public name's Python wrapper costs as much as the count (~0.3 us a step)
_count_nonzero = getattr(np._core.multiarray, "count_nonzero", np.count_nonzero)
_le = np.less_equal


@dataclass(frozen=True)
class SafetySetup:
    """The run's safety layer as set up — its rules, limits and what it is wired to — which does not change while a
    run goes; each run session makes its own :class:`SafetyLayer` from it (:meth:`layer`), holding what does."""

    robot: RobotModel
    config: SafetyConfig
    gravity: Callable[[np.ndarray], np.ndarray] | None = None
    hand: Callable[[np.ndarray], np.ndarray] | None = None
    dt: float = 1e-3
    delay: float = 0.0  # the backend's loop delay beyond the control period [s] (SafetyLayer.allow_for_delay)
    joint_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None
    push_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None
    on_yield: Callable[[bool], None] | None = None

    def layer(self) -> SafetyLayer:
        """A layer standing at a run's start: not tripped, no event yet."""
        layer = SafetyLayer(self.robot, self.config, self.gravity, self.hand, self.dt)
        layer.joint_torque, layer.push_torque, layer.on_yield = self.joint_torque, self.push_torque, self.on_yield
        layer.allow_for_delay(self.delay)
        return layer

    @property
    def limits(self) -> JointLimits:
        """The ranges, speeds and torques a run keeps to (the robot's, narrowed)."""
        return self.robot.limits

    @property
    def keep_in(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The keep-in box's world corners (min, max), if there is one."""
        box = self.config.keep_in
        return world_box(box, self.robot.base_pose) if box is not None else None

    @property
    def categories(self) -> dict[str, int]:
        """The stop category of each rule."""
        return stop_categories(self.robot, self.config)


class SafetyLayer(RunState):
    """Checks every command (the rules: the module docstring) against the limits of ``robot`` (the runner narrows
    them first); ``hand(q)``: the hand's world position, for a keep-in box; ``dt`` tells one clipping episode from
    the next. How it stops the robot is its ``stopping`` (:class:`~rehabkit.core.safety.stopping.Stopping`), its soft
    start and stop its ``ramps`` (:class:`~rehabkit.core.safety.ramps.Ramps`). It is a run's: its state —
    tripped or not, the events, the stop and ramps under way — is taken and put back with the session's
    (``run_state``)."""

    RUN_STATE_NESTED = ("stopping", "ramps", "compliance", "_clipping", "_breaches")
    RUN_STATE_FIELDS = ("events", "interventions", "tripped_at", "compliance", "saturated_steps", "_plain",
                        *RUN_STATE_NESTED)

    def __init__(self, robot: RobotModel, config: SafetyConfig, gravity=None,
                 hand: Callable[[np.ndarray], np.ndarray] | None = None, dt: float = 1e-3):
        lim = robot.limits
        # (a revolute joint's margin in degrees, a prismatic joint's in metres)
        margin = np.where(robot.revolute, math.radians(config.position_margin_deg), config.position_margin_m)
        self.names = robot.joint_names
        self._revolute = robot.revolute
        self.limits = lim  # the ranges, speeds and torques the run keeps to (the envelope's where narrower)
        self.lo, self.hi = lim.lower - margin, lim.upper + margin
        self.vmax = lim.velocity * config.velocity_factor
        self.effort = lim.effort
        self._breaches = Breaches(JointLimits(self.lo, self.hi, self.vmax, self.effort), self.names, self._revolute)
        self.config = config
        self.events: list[SafetyEvent] = []  # trips
        self.interventions: list[SafetyEvent] = []  # every time the layer changed a command: trips, clipping, ramps
        # (the list's own append, not self._note: a bound method of the layer's would be a reference cycle)
        self.stopping = Stopping(robot, config, self.lo, self.hi, gravity, dt, self.interventions.append)
        self.ramps = Ramps(config, self.stopping.hold_torque, self.interventions.append)
        self.tripped_at: float | None = None
        self.compliance: Compliance | None = None  # a force-limiting reaction under way (instead of a stop)
        # the joint torques the interaction force exerts, (q, force) -> tau: a retreat's direction (the runner
        # sets it from the force's source)
        self.joint_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None
        self.push_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None  # all of it, now
        # told when a yield begins and ends (True/False): a robot side that bridges gaps in the commands on its own
        # then bridges them yielding (the runner sets it for a backend that can: CompliantGaps)
        self.on_yield: Callable[[bool], None] | None = None
        # told each trip before the layer acts on it (the run's safety log: on disk first); an error of its own is
        # logged, and the stop goes on
        self.on_event: Callable[[SafetyEvent], None] | None = None
        self._robot = robot
        self.saturated_steps = 0
        self._dt, self._gain_dt = dt, dt
        self._clipping = Clipping(self.names, self.effort, dt, self.interventions.append)
        self._box = KeepIn(config.keep_in, robot.base_pose, hand) if config.keep_in is not None else None
        # the fast path tests lower <= [q, qd, tau] <= upper in two comparisons (NaN fails both; an unbounded
        # joint's infinite range passes), counted: ~0.6 µs a step against ~0.8 for |row - centre| <= half-width
        n = robot.dof
        self._n = n
        lower = np.concatenate([self.lo, -self.vmax, -self.effort])
        upper = np.concatenate([self.hi, self.vmax, self.effort])
        self._fast = (lower, upper, np.empty(3 * n, dtype=bool), np.empty(3 * n, dtype=bool), 6 * n,
                      slice(2 * n, None))
        self._plain = False  # set once the start is behind and no box or ramp needs a look each step

    @property
    def tripped(self) -> bool:
        return self.tripped_at is not None

    @property
    def category(self) -> int | None:
        """The category of the stop under way (None before a trip, or while a force-limiting reaction lasts)."""
        return self.stopping.category

    @property
    def reaction(self) -> str | None:
        """The force-limiting reaction under way (``yield``/``retreat``), if any."""
        return self.compliance.kind if self.compliance is not None else None

    @property
    def categories(self) -> dict[str, int]:
        """The stop category of each rule."""
        return dict(self.stopping.by_rule)

    @property
    def torque_off(self) -> bool:
        """Tripped, and the torque has gone off (category 0, or 1 once stopped): the brakes are due."""
        return self.tripped_at is not None and self.stopping.torque_off

    def braked(self, t: float, engaged: bool) -> None:
        """Record that the torque went off, and whether brakes hold the robot."""
        self.stopping.braked(t, engaged)

    def require_ramp_in(self, seconds: float) -> None:
        """Ramp in at least this long (the first session after an e-stop was cleared)."""
        if self.ramps.require_ramp_in(seconds):
            self._plain = False

    def begin_ramp_out(self, t: float, q: np.ndarray) -> None:
        """Start the soft stop: over ``ramp_out_s`` the torque blends into holding posture ``q``."""
        if self.tripped_at is None and self.ramps.begin_ramp_out(t, q):
            self._plain = False

    @property
    def keep_in(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The keep-in box's world corners (min, max) the hand is watched against, if there is one."""
        return self._box.corners if self._box is not None else None

    def target(self, t: float, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The position and velocity targets a joint on its own servo loop may follow at ``t`` (after
        :meth:`check_row` of the same step): the reference within the range and the speed limits, or once tripped the
        stop's ramp and then the held posture."""
        if self.tripped_at is not None:
            return self.stopping.target(t, q)
        lim = self.limits
        return np.clip(q_ref, lim.lower, lim.upper), np.clip(qd_ref, -lim.velocity, lim.velocity)

    def allow_for_delay(self, delay: float) -> None:
        """The backend's loop delay beyond the control period [s]: the holds' gains stay stable with it, a stop's
        ramp lasts long enough for it."""
        self._gain_dt = self.stopping.gain_dt = self._dt + delay

    def check_row(self, t: float, row: np.ndarray) -> np.ndarray:
        """Check a packed ``[q, qd, tau]`` row; its torque part is overwritten with what to send.

        The runner records rows straight into its trace, so checking costs no copy.
        """
        if self.tripped_at is None:
            lower, upper, above, below, both, torque = self._fast
            # (positional out= arguments: the keyword costs ~0.05 µs each; all(): 0.5 µs more than a count)
            if _count_nonzero(_le(lower, row, above)) + _count_nonzero(_le(row, upper, below)) == both:
                tau = row[torque]
                if self._plain:  # no keep-in box, started, ramp-in over, no ramp-out: nothing else to do
                    return tau
                n, ramps = self._n, self.ramps
                self._plain = self._box is None and ramps.start_q is not None and not ramps.due(t)
                if self._box is not None and self._outside_box(t, row[:n], row[n : 2 * n]):
                    tau[:] = self.stopping.torque(t, row[:n], row[n : 2 * n])
                    return tau
                if ramps.start_q is None:
                    ramps.start_q = row[:n].copy()
                if ramps.due(t):
                    ramps.apply(t, row[:n], row[n : 2 * n], tau)
                return tau
        n = self._n
        q, qd, tau = row[:n], row[n : 2 * n], row[2 * n :]
        if self.compliance is not None:
            tau[:] = self._comply(t, q, qd)
            return tau
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
                    self._clipping.step(t, tau, over)
                    np.clip(tau, -self.effort, self.effort, out=tau)
                    if self._box is not None and self._outside_box(t, q, qd):
                        tau[:] = self.stopping.torque(t, q, qd)
                    return tau
                j = int(np.argmax(over))
                self._breach(t, q, LimitBreach("torque", self.names[j], float(tau[j]), float(self.effort[j]),
                                               revolute=bool(self._revolute[j])), "commanded", qd)
            else:
                self._diagnose(t, q, qd, tau)
        elif (breach := self._breaches.during_stop(q, qd)) is not None:  # a limit the stop did not hold: said
            self._breach(t, q, breach, "measured", qd)
        tau[:] = self.stopping.torque(t, q, qd)
        return tau

    def check_force(self, t: float, q: np.ndarray, force: np.ndarray, qd: np.ndarray | None = None) -> None:
        """Trip if the interaction force at the hand (world frame [N]) is above the envelope's limit."""
        limit = self.config.interaction_force_n
        if self.compliance is not None:
            self.compliance.observe(t, q, force)
            return
        if limit is None or self.tripped_at is not None:
            return
        magnitude = float(np.linalg.norm(force))
        if not magnitude <= limit:  # NaN trips too
            self._trip(t, q, "interaction-force", None, magnitude, limit, "interaction force above its limit",
                       {"force_n": np.round(force, 3).tolist()}, qd=qd)

    def _comply(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The reaction's torque, unless a rule it keeps is broken: then the robot stops in that rule's category."""
        broken = self.compliance.broken(t, q, qd, self.lo, self.hi, self.vmax)
        if broken is not None:
            return self._escalate(t, q, qd, *broken)
        return self.compliance.torque(t, q, qd)

    def _escalate(self, t, q, qd, rule, joint, value, limit, why) -> np.ndarray:
        """A force-limiting reaction ends in a stop (its rule's category): a trip of its own."""
        kind, self.compliance = self.compliance.kind, None
        if kind == "yield" and self.on_yield is not None:
            self.on_yield(False)
        name = self.names[joint] if isinstance(joint, int) else joint
        figure = f": {name + ' = ' if name else ''}{value:.4g} (limit {limit:.4g})" if value is not None else ""
        cause = f"while the robot {'yielded' if kind == 'yield' else 'retreated'}, {why}{figure}"
        self._stop(t, q, qd, rule, name, value, limit, cause, {"during": kind})
        return self.stopping.torque(t, q, qd)

    def trip(self, t: float, q: np.ndarray, rule: str, message: str, qd: np.ndarray | None = None,
             breach: LimitBreach | None = None, data: dict | None = None) -> None:
        """Trip from outside (a rejected plan, an external e-stop); ``qd``: the speed the controlled stop
        starts from (none: from rest); ``breach``: the limit a refused plan would have broken (its joint, value
        and limit become the event's, its quantity ``data["quantity"]``); ``data``: the rule's own fields."""
        if breach is not None:
            self._trip(t, q, rule, breach.joint, breach.value, breach.limit, message,
                       {**(data or {}), "quantity": breach.quantity, "at_s": breach.at_s}, described=True, qd=qd,
                       breach=breach)
        else:
            self._trip(t, q, rule, None, None, None, message, data, qd=qd)

    def _outside_box(self, t: float, q: np.ndarray, qd: np.ndarray) -> bool:
        found = self._box.exit(q)
        if found is not None:
            value, bound, message, data = found
            self._trip(t, q, "keep-in", None, value, bound, message, data, qd=qd)
        return found is not None

    def _diagnose(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> None:
        for name, arr in (("state position", q), ("state velocity", qd), ("command torque", tau)):
            bad = ~np.isfinite(arr)
            if bad.any():
                j = int(np.argmax(bad))
                self._trip(t, q, "non-finite", j, None, None, f"non-finite {name} ({arr[j]})", qd=qd)
                return
        self._breach(t, q, self._breaches.first(q, qd), "measured", qd)  # (what the fast path checked)

    def _breach(self, t: float, q: np.ndarray, breach: LimitBreach, what: str, qd: np.ndarray) -> None:
        """A limit rule's trip: the event's fields are the breach's, its message the breach's one wording."""
        self._trip(t, q, breach.quantity, breach.joint, breach.value, breach.limit, f"{what}: {breach.describe()}",
                   described=True, qd=qd, breach=breach)

    def _trip(self, t, q, rule, joint, value, limit, message, data=None, described=False, qd=None,
              breach=None) -> None:
        name = self.names[joint] if isinstance(joint, int) else joint
        subject = f"{name} = " if name else ""
        digits = 4 if name else 6  # positions of the hand [m]: to the micrometre
        cause = message + (f": {subject}{value:.{digits}g} (limit {limit:.{digits}g})"
                           if value is not None and not described else "")
        text = f"t={t:.3f}s: {cause}"
        self._breaches.said(rule, name)
        if self.tripped_at is not None:  # already stopping: what else happened is noted, the stop goes on
            self.interventions.append(SafetyEvent(t, rule, name, value, limit, text + "; while stopping", data or {},
                                                  cause=cause, breach=breach))
            return
        reaction = self.config.reactions.get(rule)
        if reaction is not None and reaction.type != "stop":
            words = {"yield": "yield: compliant, gravity compensated, no stop",
                     "retreat": "retreat: away along the force, then hold"}[reaction.type]
            self._record(SafetyEvent(t, rule, name, value, limit, f"{text}; {words}",
                                     {**(data or {}), "reaction": reaction.type}, cause=cause, breach=breach))
            self.tripped_at = t
            self.compliance = Compliance.start(reaction, float(self.config.interaction_force_n), t, q, self._robot,
                                               self.lo, self.hi, self.stopping.gravity, self.config, self.joint_torque,
                                               qd, self.push_torque, self._gain_dt)
            if reaction.type == "yield" and self.on_yield is not None:
                self.on_yield(True)
            return
        self.tripped_at = t
        self._stop(t, q, qd, rule, name, value, limit, cause, data, breach)

    def _stop(self, t, q, qd, rule, name, value, limit, cause, data=None, breach=None) -> None:
        """The stop a trip begins (its rule's category), as an event: a rule broken, or a reaction that ended in one."""
        category = self.stopping.category_of(rule)
        try:
            self._record(SafetyEvent(t, rule, name, value, limit, f"t={t:.3f}s: {cause}; {WORDS[category]}",
                                     {**(data or {}), "category": category}, cause=cause, breach=breach))
        finally:  # (recorded first; begun whatever the recording met: Ctrl-C as it wrote, say)
            self.stopping.begin(t, category, q, qd)

    def _record(self, event: SafetyEvent) -> None:
        """A trip: in the events and the interventions, and told to ``on_event`` before the layer acts on it."""
        self.events.append(event)
        self.interventions.append(event)
        if self.on_event is not None:
            try:
                self.on_event(event)
            except Exception:  # noqa: BLE001 (the record's trouble must not hold up the stop)
                logging.getLogger(__name__).exception("telling the trip at t=%.3f s to the safety log failed", event.t)

    @property
    def growing(self) -> SafetyEvent | None:
        """The torque-clipping episode under way, which may still grow (none once tripped: no clipping since)."""
        return self._clipping.episode if self.tripped_at is None else None

