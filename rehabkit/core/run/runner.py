"""Run one scenario: assemble, plan, loop, finish.

The data flow, in order: validated scenario → :func:`~rehabkit.core.setup.assembly.assemble`
(robot, narrowed limits, plugins, safety layer, admitted targets) → first plan →
:func:`~rehabkit.core.run.loop.run_loop` (events → sensors → controller → safety layer →
backend) → :class:`~rehabkit.core.results.record.RunRecord` → metrics, ``summary.json`` with
the ``expect:`` verdicts, and the Rerun log alongside. The loop calls plugin objects
directly; pluggy only finds them, and calls the extensions at setup and at the end.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import yaml
from threadpoolctl import threadpool_limits

from rehabkit.core.io import atomic_write_json, atomic_write_text
from rehabkit.core.kinds.capabilities import NamedJoints, PassiveJoints
from rehabkit.core.kinds.interfaces import BackendFaultError, Plan, PlanningError, Target
from rehabkit.core.log import safety_log
from rehabkit.core.log.rerun_log import encode_images
from rehabkit.core.log.run_view import RunView
from rehabkit.core.plugins.lifecycle import Extensions, default_extensions
from rehabkit.core.plugins.registry import PluginRegistry, default_registry
from rehabkit.core.results.metric import MetricCatalogue
from rehabkit.core.results.metrics import Trace
from rehabkit.core.results.record import RunRecord
from rehabkit.core.results.summary import RunResult, finish
from rehabkit.core.run.loop import run_loop
from rehabkit.core.run.plan_gate import PlanGate
from rehabkit.core.run.reference import ReferenceBuffer
from rehabkit.core.run.sensor_threads import SensorThreads
from rehabkit.core.run.timeline import Timeline
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.setup.assembly import (
    Assembly,
    SetupError,
    assemble,
    first_plan_refusal,
    metric_catalogue,
    start_posture,
)

_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's emitter where installed
SNAPSHOT = "scenario.yaml"  # the scenario as run, in the run's folder: what `rehabkit replay` starts from

__all__ = ["SNAPSHOT", "Runner", "RunResult", "SetupError"]


class Runner:
    """Runs one loaded scenario; ``build()`` alone assembles it (plugins built, nothing run)."""

    def __init__(self, scenario: LoadedScenario, registry: PluginRegistry | None = None,
                 out_dir: Path | None = None, spawn: bool = False, progress: bool = False,
                 extensions: Extensions | None = None):
        self.loaded, self.sc = scenario, scenario.model
        self.registry = registry or default_registry()
        self.extensions = extensions or default_extensions()
        self.out_dir, self.spawn, self.progress = out_dir, spawn, progress
        self.setup: Assembly | None = None
        self.notes: list[dict] = []
        self._no_plan: str | None = None  # why the first plan failed: then no expectation is met
        self._failed_plan: Exception | str | None = None  # the last plan's failure
        self.refusal: ScenarioError | None = None  # the first plan's failure, located in the scenario file
        self.view: RunView | None = None

    # the assembled plugins, for callers that inspect a run
    robot = property(lambda self: self.setup.robot)
    backend = property(lambda self: self.setup.backend)
    sensors = property(lambda self: self.setup.sensors)
    observations = property(lambda self: self.timeline.observations)

    def build(self) -> Assembly:
        """Assemble the run (see :mod:`rehabkit.core.setup.assembly`)."""
        if broken := self.extensions.broken:
            raise SetupError("; ".join(f"extension '{b.name}' failed to load: {b.error}" for b in broken)
                             + " (fix or uninstall it)")
        self.setup = assemble(self.loaded, self.registry, self.extensions, self.out_dir,
                              plan=self.plan_for_controller, note=self.note)
        return self.setup

    def note(self, t: float, text: str) -> None:
        """A plugin's message for people (an HMI display line): kept in the summary and the log."""
        self.notes.append({"t": round(t, 6), "text": text})
        if self.view is not None and self.view.log:
            self.view.log.event(t, text, level="INFO")

    def run(self) -> RunResult:
        """Build, run and finish; outputs are complete files or none."""
        threads = None
        try:
            t_setup = time.perf_counter()
            threads = self.start()
            a, trace, packed, catalogue = self.setup, self.trace, self.packed, self.catalogue
            # a control loop's matrices are small: BLAS worker threads only spin against it, and against a bridge or
            # renderer sharing the machine (L-Exos over the lock-step link 24.4 -> 13.6 s; in simulation 7.8 -> 7.0 s)
            with threadpool_limits(limits=1, user_api="blas"):
                result = run_loop(a, trace, packed, self.ref, self.timeline, self.view, self.progress)
            extra = {}
            if threads is not None:  # no reading in flight while the run is summed up
                threads.close()
                extra = {f"sensor_overruns_{name}": float(threads.overruns[name])
                         for name in a.sensors if name in threads}
            return self._finish(trace, result, result.started - t_setup, extra, catalogue)
        except BaseException:
            if self.view is not None and self.view.log is not None:
                self.view.log.discard()
            raise
        finally:
            if threads is not None:
                threads.close()

    def start(self) -> SensorThreads | None:
        """Build, plan and stand at the start, the loop not yet run: what :meth:`run` does first, and what a
        learning environment does at each reset (it then runs the loop a policy period at a time with
        :func:`~rehabkit.core.run.loop.run_loop`'s ``k_to``). Returns the sensor threads of a real-time run."""
        a = self.build()
        self.catalogue = metric_catalogue(a)
        self.gate = PlanGate(a, self.catalogue)
        self.trace, self.packed = self._start()
        threads = None
        if a.backend.realtime and any(s.blocking for s in a.sensors.values()):
            threads = SensorThreads([name for name, s in a.sensors.items() if s.blocking],
                                    prepare=encode_images if self.view.log else None)
        self.timeline = Timeline(a, self._replan, self.view.log, threads)
        self._first_plan()
        return threads

    # -- start: the trace, the reference, the first plan --------------------

    def _start(self) -> tuple[Trace, np.ndarray]:
        a, sc = self.setup, self.sc
        n, dof = a.schedule.steps, a.robot.model.dof
        # q, qd, tau of a step sit side by side: the safety layer checks that row in place
        packed = np.zeros((n, 3 * dof))
        trace = Trace(np.arange(n) * a.schedule.control_dt, packed[:, :dof], packed[:, dof : 2 * dof],
                      packed[:, 2 * dof :], np.zeros((n, dof)), np.zeros((n, dof)),
                      tau_h=np.zeros((n, dof)) if a.patient is not None else None,
                      f_h=np.zeros(n) if a.force_measured else None)
        self.view = RunView(a, self.spawn)
        self.q0 = q0 = start_posture(a)
        try:
            a.backend.reset(q0)
        except BackendFaultError as exc:
            raise SetupError(f"backend '{sc.backend.type}': {exc}") from exc
        if a.backend.ramp_in_after_clear:  # the first session after an e-stop was cleared eases in
            a.safety.require_ramp_in(a.backend.ramp_in_after_clear)
        if isinstance(a.robot, PassiveJoints) and isinstance(a.backend, NamedJoints):
            # parallel mechanisms: the passive joints assembled too, where the backend sets joints by name
            a.backend.set_joints(a.robot.passive_state(q0))
        cart = a.planner.space == "cartesian"
        start = a.robot.fk(q0)[:3, 3] if cart else q0  # Cartesian references are in the robot base frame
        hand = (lambda p: np.asarray(p, float)) if cart else (lambda q: a.robot.fk(q)[:3, 3])  # noqa: E731
        self.ref = ReferenceBuffer(n, start, a.schedule.control_dt, hand)
        ref_q, ref_qd, _ = self.ref.views()
        if cart:
            trace.x, trace.x_ref = np.zeros((n, 3)), ref_q
            trace.q_ref[:] = q0  # filled from the controller's own joint reference, when it has one
        elif a.controller.own_reference:  # the controller's own reference is what it tracked; record that
            trace.q_ref, trace.qd_ref = np.zeros((n, dof)), np.zeros((n, dof))
        else:
            trace.q_ref, trace.qd_ref = ref_q, ref_qd
        self.plans: list[dict] = []
        return trace, packed

    def _first_plan(self) -> None:
        a = self.setup
        self._replan(0, 0.0, self.q0, np.zeros(a.robot.model.dof), self.sc.task.order())
        self._no_plan = (self._refusal or "stopped before it moved") if a.safety.tripped else None
        if a.safety.tripped and a.limit_sources.by_joint:  # refused before it runs, not stopped at t=0
            raise SetupError(f"{self._refusal} (joint limits narrowed by the patient's profile or the safety "
                             "envelope)", self._refused)
        if self._failed_plan is not None:  # the task as written can't be planned: bad input, said where
            self.refusal = first_plan_refusal(a, self._failed_plan)
        if self.view.log:
            self.view.planner_drawings()

    # -- planning -----------------------------------------------------------

    def _replan(self, k: int, t: float, q: np.ndarray, qd: np.ndarray, names: list[str],
                event: int | None = None) -> None:
        """Plan through the named targets from the current state and follow it from step ``k`` (by the planner
        with event ``event``'s settings, when it has some); a plan that can't be made or must not run stops the
        robot, saying why."""
        a, self._refused = self.setup, None
        for name in names:  # sensor-driven targets take their latest sensed position
            spec = self.timeline.specs[name]
            if spec.sensor:
                pos = self.timeline.sensed(name)
                if pos is None:
                    self._stop(t, q, f"target '{name}': sensor '{spec.sensor}' has not seen it")
                    return
                pose = np.eye(4)
                pose[:3, 3] = pos
                a.targets[name] = Target(name, pose=pose, position_only=True)
        try:
            plan = self.gate.ask(t, q, qd, [a.targets[n] for n in names], a.event_planners.get(event))
        except PlanningError as exc:
            self._failed_plan = exc
            self._stop(t, q, f"planner failed: {exc}")
            return
        problem, self._refused = self.gate.problem(plan)
        if problem:
            self._failed_plan = problem
            self._stop(t, q, problem, "; not executed")
            return
        self.gate.warn_box(t, plan, a.robot.model.to_world)
        self._announce(k, self.gate.account(plan), self.ref.install(k, plan))
        self.timeline.following(names, t, plan.waypoint_times)

    def _stop(self, t: float, q: np.ndarray, why: str, then: str = "") -> None:
        self._refusal = why
        self.setup.safety.trip(t, q, "plan", why + then)

    def plan_for_controller(self, t: float, q: np.ndarray, qd: np.ndarray, targets: list[Target]) -> Plan:
        """A plan a controller asks for (e.g. a keypad's replay); it follows the trajectory itself.

        Checked against the joint limits, logged and listed in the summary like the runner's own plans.
        Raises :class:`PlanningError` with the reason when there is none.
        """
        plan = self.gate.ask(t, q, qd, targets)
        problem, _ = self.gate.problem(plan)
        if problem:
            raise PlanningError(problem)
        k0 = int(round(t / self.setup.schedule.control_dt))
        x = self.ref.sample(plan, k0)
        self.ref.add_movements(k0, plan, x)
        self._announce(k0, self.gate.account(plan), x)
        return plan

    def _announce(self, k0: int, plan: Plan, x: np.ndarray) -> None:
        """List a plan in the summary, schedule its scene actions and draw it."""
        dt, cart = self.setup.schedule.control_dt, self.setup.planner.space == "cartesian"
        self.timeline.schedule_actions(k0, plan.actions)
        way = plan.waypoints
        entry = {"t": round(k0 * dt, 6), "duration_s": plan.trajectory.duration}
        if way is not None:
            entry["waypoints_m" if cart else "waypoints_deg"] = np.round(way if cart else np.degrees(way), 6).tolist()
        self.plans.append({**entry, **{k: v for k, v in plan.diagnostics.items() if isinstance(v, (int, float))},
                           **plan.details})
        if self.view.log:
            self.view.plan(k0 * dt, plan, x)

    # -- finish -------------------------------------------------------------

    def _finish(self, trace: Trace, loop, setup_s: float, extra: dict, catalogue: MetricCatalogue) -> RunResult:
        a, k = self.setup, loop.steps
        trace = trace.trimmed(k)
        if a.planner.space == "cartesian":
            base = a.robot.model.base_pose
            trace.x[:] = (trace.x - base[:3, 3]) @ base[:3, :3]
            if a.controller.joint_reference is None:  # a controller without a joint reference: no joint tracking
                trace.q_ref[:] = np.nan
        if self.view.log:
            self.view.executed(trace, k)
        tl = self.timeline
        record = RunRecord(trace, loop.wall_s, setup_s, loop.contact_steps, self.ref.goal, self.ref.movements,
                           self.plans, self.gate.metrics, tl.fired, tl.acted, self.notes, self.gate.warnings, extra,
                           no_plan=self._no_plan)
        summary = finish(a, record, catalogue, self.view)
        if self.out_dir is not None:
            if self.view.log:
                self.view.log.close()
                summary["outputs"] = {"rrd": "run.rrd"}
            summary.setdefault("outputs", {})["scenario"] = SNAPSHOT
            snapshot = (f"# {self.loaded.path} as this run used it (extends merged, profile inlined, --set applied); "
                        "`rehabkit replay` reads it\n" + yaml.dump(self.loaded.source.data, Dumper=_DUMPER,
                                                                    sort_keys=False))
            atomic_write_text(self.out_dir / SNAPSHOT, snapshot)
            # the tamper-evident record of the run's safety (rehabkit audit), its last hash in the summary
            summary["outputs"]["safety_log"] = safety_log.LOG
            summary["safety_log_hash"] = safety_log.write(self.out_dir / safety_log.LOG,
                                                          safety_log.run_records(a, snapshot, summary))
            atomic_write_json(self.out_dir / "summary.json", summary)
        a.backend.close()
        return RunResult(summary, trace, self.out_dir, self.refusal)
