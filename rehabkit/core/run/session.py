"""One run's state, as MuJoCo's ``MjData`` is to its constant ``MjModel``: what changes while the run goes.

The :class:`~rehabkit.core.setup.assembly.Assembly` is what the run is made of and does not change; a
:class:`RunSession` is everything the run writes as it goes — the trace, the reference, the timeline, the plans,
the recording, the notes, why a plan was refused, where the loop stands. :func:`open_session` makes one standing
at the start with its first plan; :func:`~rehabkit.core.run.loop.run_loop` advances it; the runner's
``finish`` turns it into the summary. Plans are made here: at the start, on what the timeline says is due, and
when a controller asks for one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from rehabkit.core.io import atomic_write_text
from rehabkit.core.kinds.capabilities import NamedJoints, PassiveJoints
from rehabkit.core.kinds.interfaces import BackendFaultError, Plan, PlanningError, Target
from rehabkit.core.kinds.metric import MetricCatalogue
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.log.run_view import NullView, RunView, open_view
from rehabkit.core.log.safety_log import SNAPSHOT, SafetyLog, open_log
from rehabkit.core.run.plan_gate import PlanGate
from rehabkit.core.run.plugin_fault import plugin_fault
from rehabkit.core.run.reference import ReferenceBuffer
from rehabkit.core.run.sensor_threads import SensorThreads
from rehabkit.core.run.timeline import Replan, Timeline
from rehabkit.core.safety.layer import SafetyLayer
from rehabkit.core.safety.limit_breach import LimitBreach
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.setup.assembly import Assembly, SetupError
from rehabkit.core.setup.first_plan import breach_refusal, first_plan_refusal, start_posture


@dataclass(frozen=True)
class PlanRefusal:
    """Why a plan did not run: what was said (the safety stop's message), the joint limit it would have broken
    when that is why, the planner's own error when it failed, and — for the run's first plan — the refusal located
    in the scenario file (the task as written can't be planned: bad input)."""

    t: float
    reason: str
    breach: LimitBreach | None = None
    error: PlanningError | None = None
    actions: tuple[str, ...] = ()  # scene actions the plan asked for that the backend can't do
    first: bool = False
    located: ScenarioError | None = None

    @property
    def unplannable(self) -> bool:
        """The planner failed, or its plan must not run (not: a sensed target not seen yet)."""
        return self.error is not None or self.breach is not None or bool(self.actions)


@dataclass
class LoopState:
    """Where a loop run in parts stands between them."""

    k: int = 0  # the next step to run
    due: int = 0  # the next step with something due besides the control (events, sensors)
    contact_steps: int = 0
    first_contact: dict | None = None  # when, what and where the robot first touched something
    failed: bool = False  # the controller raised: the safety layer drives from then on
    stopped: bool = False  # ended for good: a stop event, a backend fault, or the safety stop has run its course
    braked: bool = False  # the torque went off after a trip and the brakes (if any) were applied
    next_log: int | None = None  # the next step logged (None: from the start)


@dataclass
class RunSession:
    """A run in progress (see the module's docstring); ``setup`` is what it runs."""

    # what of the session itself changes while it runs, as a snapshot takes it (core/run/snapshot.py): the rest it
    # holds is the Assembly's, or a part taken on its own
    RUN_STATE_FIELDS: ClassVar[tuple[str, ...]] = ("plans", "notes", "refusal", "targets", "force", "q0")

    setup: Assembly
    trace: Trace
    packed: np.ndarray  # the trace's [q, qd, tau] rows side by side: the safety layer checks a row in place
    ref: ReferenceBuffer
    view: RunView | NullView
    catalogue: MetricCatalogue
    gate: PlanGate
    q0: np.ndarray
    safety: SafetyLayer  # the run's safety layer (made from the Assembly's SafetySetup): tripped or not, its events
    timeline: Timeline | None = None
    threads: SensorThreads | None = None
    taps: list = field(default_factory=list)  # extensions' RunTaps: each reading as it is taken
    extension_states: dict = field(default_factory=dict)  # each extension's ExtensionState for this run (its tap)
    loop: LoopState = field(default_factory=LoopState)
    plans: list[dict] = field(default_factory=list)
    notes: list[dict] = field(default_factory=list)
    refusal: PlanRefusal | None = None  # the last plan that did not run, and why (the first plan's, if it did not)
    # the task's targets as the run knows them: the admitted ones, a sensed one where it was last seen (the Assembly
    # keeps what was admitted; a run writes here)
    targets: dict[str, Target] = field(default_factory=dict)
    force: np.ndarray | None = None  # the interaction force the safety layer checked last (Context.interaction_force)
    safety_log: SafetyLog | None = None  # written as the run goes, where it has a folder (the finish closes it)

    @property
    def first_refusal(self) -> PlanRefusal | None:
        """The run's first plan did not run: the robot never moved."""
        return self.refusal if self.refusal is not None and self.refusal.first else None

    # -- planning ------------------------------------------------------------------------------------------

    def act(self, k: int, t: float, q: np.ndarray, qd: np.ndarray, replans: list[Replan]) -> None:
        """Make the plans the timeline found due; a planner that crashes stops the robot, saying so."""
        try:
            for request in replans:
                self.replan(k, t, q, qd, request)
        except Exception as exc:
            a = self.setup
            said, data = plugin_fault(a.registry, "planner", a.sc.planner.type, exc)
            self.safety.trip(t, q, "plugin-error", said, qd, data=data)

    def replan(self, k: int, t: float, q: np.ndarray, qd: np.ndarray, request: Replan, first: bool = False) -> None:
        """Plan through the request's targets from the current state and follow it from step ``k`` (by the planner
        with its event's settings, when it has some); a plan that can't be made or must not run stops the robot,
        saying why."""
        a = self.setup
        if request.unseen is not None:
            self._refuse(PlanRefusal(t, request.unseen, first=first), q)
            return
        for name, pos in request.sensed.items():  # sensor-driven targets at their latest sensed position
            pose = np.eye(4)
            pose[:3, 3] = pos
            self.targets[name] = Target(name, pose=pose, position_only=True)
        try:
            plan = self.gate.ask(t, q, qd, [self.targets[n] for n in request.names],
                                 a.event_planners.get(request.event))
        except PlanningError as exc:
            self._refuse(PlanRefusal(t, f"planner failed: {exc}", error=exc, first=first), q)
            return
        problem, breach, actions = self.gate.problem(plan, t)
        if problem:
            self._refuse(PlanRefusal(t, problem, breach=breach, actions=actions, first=first), q, "; not executed")
            return
        if (warning := self.gate.warn_box(t, plan)) is not None:  # (the terminal's PLAN line, said in the recording)
            self.view.event(t, f"PLAN {warning}", level="WARN")
        self._announce(k, self.gate.account(plan), self.ref.install(k, plan, request.names))
        self.timeline.following(request.names, t, plan.waypoint_times)

    def _refuse(self, refusal: PlanRefusal, q: np.ndarray, then: str = "") -> None:
        if refusal.first and refusal.unplannable:  # the task as written can't be planned: bad input, said where
            failure = refusal.error if refusal.error is not None else refusal.reason
            refusal = replace(refusal, located=first_plan_refusal(self.setup, failure))
        if self.first_refusal is None:  # (the first plan's refusal is kept: the robot never moved)
            self.refusal = refusal
        data = {"actions": list(refusal.actions)} if refusal.actions else {}
        error = refusal.error
        if error is not None:  # the planner's cause and setting as fields (its message says them in words)
            if error.code:
                data["cause"] = error.code
            if error.setting:
                data["setting"] = ".".join(str(part) for part in error.setting)
        self.safety.trip(refusal.t, q, "plan", refusal.reason + then, breach=refusal.breach, data=data or None)

    def plan_for_controller(self, t: float, q: np.ndarray, qd: np.ndarray, targets: list[Target]) -> Plan:
        """A plan a controller asks for (e.g. a keypad's replay); it follows the trajectory itself.

        Checked against the joint limits, logged and listed in the summary like the run's own plans.
        Raises :class:`PlanningError` with the reason when there is none.
        """
        plan = self.gate.ask(t, q, qd, targets)
        problem, _, _ = self.gate.problem(plan, t)
        if problem:
            raise PlanningError(problem)
        k0 = int(round(t / self.setup.schedule.control_dt))
        x = self.ref.sample(plan, k0)
        self.ref.add_movements(k0, plan, x, [t.name for t in targets])
        self._announce(k0, self.gate.account(plan), x)
        return plan

    def _announce(self, k0: int, plan: Plan, x: np.ndarray) -> None:
        """List a plan in the summary, schedule its scene actions and draw it."""
        dt, space = self.setup.schedule.control_dt, self.setup.space
        self.timeline.schedule_actions(k0, plan.actions)
        entry = {"t": round(k0 * dt, 6), "duration_s": plan.trajectory.duration}
        if plan.waypoints is not None:
            entry[space.waypoint_key] = np.round(space.waypoint_scale(plan.waypoints), 6).tolist()
        self.plans.append({**entry, **{k: v for k, v in plan.diagnostics.items() if isinstance(v, (int, float))},
                           **plan.details})
        self.view.plan(k0 * dt, plan, x)

    def note(self, t: float, text: str) -> None:
        """A plugin's message for people (an HMI display line): kept in the summary and the recording."""
        self.notes.append({"t": round(t, 6), "text": text})
        self.view.event(t, text, level="INFO")


def open_session(a: Assembly, spawn: bool = False, notes: list[dict] | None = None) -> RunSession:
    """The run standing at its start: the trace and reference allocated, the recording open, the robot at the
    start posture (an e-stop cleared since the last session eases in), the first plan made. ``notes`` are those
    said while the run was assembled."""
    n, dof = a.schedule.steps, a.robot.model.dof
    packed = np.zeros((n, 3 * dof))
    trace = Trace(np.arange(n) * a.schedule.control_dt, packed[:, :dof], packed[:, dof : 2 * dof],
                  packed[:, 2 * dof :], np.zeros((n, dof)), np.zeros((n, dof)),
                  tau_h=np.zeros((n, dof)) if a.patient is not None else None,
                  f_h=np.zeros(n) if a.force_source is not None and a.force_source.measured else None)
    view = open_view(a, spawn)
    try:
        return _standing(a, view, trace, packed, notes)
    except BaseException:  # no session for the runner to discard: its recording (and any taps) dropped here
        view.discard()
        raise


def _standing(a: Assembly, view, trace: Trace, packed: np.ndarray, notes: list[dict] | None) -> RunSession:
    n = a.schedule.steps
    q0 = start_posture(a)
    try:
        a.backend.reset(q0)
    except BaseException as exc:  # no session: what the backend holds (a bridge, a bus, drives) is released
        a.backend.close()
        if isinstance(exc, BackendFaultError):
            raise SetupError(f"backend '{a.sc.backend.type}': {exc}") from exc
        raise
    safety = a.safety.layer()
    if a.backend.ramp_in_after_clear:  # the first session after an e-stop was cleared eases in
        safety.require_ramp_in(a.backend.ramp_in_after_clear)
    if isinstance(a.robot, PassiveJoints) and isinstance(a.backend, NamedJoints):
        # parallel mechanisms: the passive joints assembled too, where the backend sets joints by name
        a.backend.set_joints(a.robot.passive_state(q0))
    ref = ReferenceBuffer(n, a.space.point(q0), a.schedule.control_dt, a.space.hand)
    ref_q, ref_qd, _ = ref.views()
    a.space.allocate(trace, ref_q, ref_qd)
    catalogue = a.catalogue  # (made once, at assembly: validate's and the run's are one)
    session = RunSession(a, trace, packed, ref, view, catalogue, PlanGate(a, a.space, catalogue), q0, safety,
                         notes=list(notes or []), targets=dict(a.targets))
    session.taps, session.extension_states = a.extensions.run_opened(a)
    for tap in session.taps:  # (the trace as the loop fills it, the movements as plans make them: written as it goes)
        tap.follow(trace, lambda: session.ref.movements)
    threads = None
    if a.backend.realtime and any(s.blocking for s in a.sensors.values()):
        prepare = None
        if view.active and not session.taps:
            # images encoded for the log where they are taken, off the loop (not when a tap takes them as they are);
            # Rerun's encoder, imported only where a recording is made
            from rehabkit.core.log.archetypes import encode_images as prepare
        threads = SensorThreads([name for name, s in a.sensors.items() if s.blocking], prepare=prepare)
    session.threads = threads
    session.timeline = Timeline(a, view, threads, session.taps, session.targets, safety)
    try:
        if a.out_dir is not None:  # the safety log from now on: the run and its limits on disk, then each trip;
            session.safety_log = open_log(a, safety)  # and the scenario as it runs (a killed run's folder keeps it)
            atomic_write_text(a.out_dir / SNAPSHOT, session.safety_log.scenario)
        _first_plan(session)
    except BaseException:
        for tap in session.taps:
            tap.discard()
        if session.safety_log is not None:  # (a run refused before it ran leaves none)
            session.safety_log.discard()
            (a.out_dir / SNAPSHOT).unlink(missing_ok=True)
        raise
    return session


def _first_plan(s: RunSession) -> None:
    a = s.setup
    s.replan(0, 0.0, s.q0, np.zeros(a.robot.model.dof), s.timeline.request(a.sc.task.order()), first=True)
    if s.safety.tripped and s.refusal is None:  # (an e-stop still latched, say)
        s.refusal = PlanRefusal(0.0, "stopped before it moved", first=True)
    if s.safety.tripped and s.refusal is not None and s.refusal.breach is not None:
        # a first plan breaking a limit in force — the robot's own or narrowed — is refused before anything runs,
        # as validate refuses it (it ran 0.5 s and wrote its files where the limit was the robot's own)
        raise breach_refusal(a, s.refusal.breach)
    if s.safety.tripped and a.limit_sources.by_joint:
        # refused before it runs (not stopped at t=0): the limits in force were narrowed, and said where
        raise SetupError(f"{s.refusal.reason} (joint limits narrowed by the patient's profile or the safety "
                         "envelope)", s.refusal.breach)
    s.view.planner_drawings()
