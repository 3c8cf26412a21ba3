"""Build a scenario's plugins and run its loop.

The data flow, in order: validated scenario → plugin instances (robot first;
the others get it in their context) → plan at start → fixed-step loop
(events → sensors → controller → safety layer → backend) → metrics →
``summary.json`` with the ``expect:`` verdicts, and the Rerun log alongside.
The loop calls plugin objects directly; pluggy is only used to find them.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from rehabkit.core.interfaces import BackendFaultError, Context, Plan, PlanningError, PlanRequest, Target
from rehabkit.core.io import atomic_write_json, atomic_write_text
from rehabkit.core.log import RerunLog, encode_images
from rehabkit.core.metrics import Trace
from rehabkit.core.plugins import PluginRegistry, default_registry, suggest
from rehabkit.core.results import RunResult, build_summary, collect_metrics
from rehabkit.core.safety import AXES, SafetyLayer
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.sensor_threads import SensorThreads
from rehabkit.core.targets import resolve_targets
from rehabkit.rehab.admission import adapt_segments, admit_targets, hand_in_world, narrowed_limits
from rehabkit.rehab.patient import interaction_force_limit
from rehabkit.rehab.run_outcomes import HandForce, Reach, outcome_series

SNAPSHOT = "scenario.yaml"  # the scenario as run, in the run's folder: what `rehabkit replay` starts from
REACH_CHECK_HZ = 100.0  # 'reached' events are tested at this rate, not every control step
LOG_FLUSH_SAMPLES = 500  # log-rate samples buffered between column sends
SCENE_ACTIONS = ("release", "grasp")  # what a plan may do to held objects (Backend methods of these names)


class SetupError(RuntimeError):
    """The scenario is valid but its plugins can't be put together (message says why)."""


def _idle(dof: int):
    zero = np.zeros(dof)
    return lambda *args: zero


@dataclass
class _Schedule:
    control_dt: float
    substeps: int
    steps: int
    log_every: int
    reach_every: int
    sensor_every: list[int] = field(default_factory=list)


class Runner:
    """Runs one loaded scenario."""

    def __init__(self, scenario: LoadedScenario, registry: PluginRegistry | None = None,
                 out_dir: Path | None = None, spawn: bool = False, progress: bool = False):
        self.loaded, self.sc = scenario, scenario.model
        self.registry = registry or default_registry()
        self.out_dir, self.spawn, self.progress = out_dir, spawn, progress
        self.observations: dict[str, dict[str, Any]] = {}
        self.notes: list[dict[str, Any]] = []
        self.plan_warnings: list[dict[str, Any]] = []  # what a plan will run into (the keep-in box)
        self.log: RerunLog | None = None

    # -- construction -------------------------------------------------------

    def _make(self, kind: str, config, ctx: Context):
        info = self.registry.get(kind, config.type)
        try:
            return info.factory(config, ctx)
        except (ValueError, PlanningError) as exc:
            raise SetupError(f"{kind} '{config.type}': {exc}") from exc

    def build(self) -> None:
        sc = self.sc
        profile = sc.patient
        self.rng = np.random.default_rng(sc.seed)
        robot_cfg, self.segments = adapt_segments(sc.robot, profile, self.loaded.source)
        ctx = Context(self.loaded.directory, self.rng, 1.0 / sc.rates.control_hz, world=sc.world,
                      out_dir=self.out_dir, robot_spec=robot_cfg.model_dump(mode="json"), seed=sc.seed,
                      safety=sc.safety, patient=profile)
        self.robot = self._make("robot", robot_cfg, ctx)
        ctx.robot = self.robot
        # the patient's range and comfort and the envelope narrow the robot's limits before anything plans with them
        self.robot_limits = self.robot.model.limits
        try:
            self.robot.model.limits, self.limit_sources = narrowed_limits(self.robot.model, profile, sc.safety,
                                                                          self.loaded.source)
        except ValueError as exc:
            raise SetupError(str(exc)) from exc
        # sensors before the backend: their instruments go into the scene it builds
        self.sensors = {name: self._make("sensor", cfg, ctx) for name, cfg in sc.sensors.items()}
        ctx.instruments = [i for s in self.sensors.values() for i in s.instruments()]
        self.backend = self._make("backend", sc.backend, ctx)
        self.planner = self._make("planner", sc.planner, ctx)
        ctx.plan, ctx.note, ctx.reference_space = self.plan_for_controller, self.note, self.planner.space
        self.controller = self._make("controller", sc.controller, ctx)
        if self.planner.space != self.controller.reference:
            raise SetupError(f"planner '{sc.planner.type}' plans in {self.planner.space} space but controller "
                             f"'{sc.controller.type}' takes {self.controller.reference} references; "
                             "pick a matching pair")
        self.patient = None
        if profile is not None and getattr(profile, "model", None) is not None:
            if self.backend.realtime:  # a real robot has a real person in it
                self.note(0.0, f"patient.model '{profile.model.type}' is not simulated on the "
                               f"'{sc.backend.type}' backend: the person is real")
            else:
                self.patient = self._make("patient", profile.model, ctx)
        force_limit = interaction_force_limit(profile, sc.safety)
        if force_limit is not None and self.patient is None:
            raise SetupError(f"an interaction-force limit ({force_limit:g} N, from safety.interaction_force_n or "
                             "patient.comfort) needs a source of the force: a simulated patient (patient.model); "
                             f"backend '{sc.backend.type}' measures none")
        self.hand_force = HandForce(self.robot.model) if force_limit is not None else None
        self.safety = SafetyLayer(self.robot.model, sc.safety.model_copy(update={"interaction_force_n": force_limit}),
                                  gravity=self.robot.gravity_torque, dt=ctx.control_dt,
                                  hand=hand_in_world(self.robot) if sc.safety.keep_in is not None else None)
        self._specs = {t.name: t for t in sc.task.targets}
        for t in sc.task.targets:
            if t.sensor and t.sensor not in self.sensors:
                raise SetupError(f"target '{t.name}' follows sensor '{t.sensor}', which is not in 'sensors'"
                                 f"{suggest(t.sensor, self.sensors)}")
        try:
            self.targets = resolve_targets(sc.task, self.robot, sc.seed)
        except PlanningError as exc:
            raise SetupError(f"task: {exc}") from exc
        self.replaced = admit_targets(self.targets, sc.task, self.robot, self.robot_limits, self.limit_sources,
                                      profile, self.loaded.source)
        self.schedule = self._schedule()

    def _schedule(self) -> _Schedule:
        sc, dt = self.sc, self.backend.timestep
        control_dt = 1.0 / sc.rates.control_hz
        sub = control_dt / dt
        if abs(sub - round(sub)) > 1e-6 or round(sub) < 1:
            raise SetupError(f"rates.control_hz = {sc.rates.control_hz} gives a period of {control_dt} s, "
                             f"not a whole multiple of the backend timestep {dt} s")
        every = [max(1, round(sc.rates.control_hz / s.rate_hz)) for s in self.sensors.values()]
        return _Schedule(control_dt, round(sub), int(round(sc.duration / control_dt)),
                         max(1, round(sc.rates.control_hz / sc.logging.rate_hz)),
                         max(1, round(sc.rates.control_hz / REACH_CHECK_HZ)), every)

    def start_q(self) -> np.ndarray:
        task = self.sc.task
        name = task.start or task.order()[0]
        target = self.targets[name]
        if target.q is not None:
            return target.q.copy()
        try:  # a Cartesian start: the robot's IK, first solution within the joint ranges
            solutions = self.robot.ik(target.pose) if target.pose is not None else []
        except NotImplementedError:
            solutions = []
        lim = self.robot.model.limits
        inside = [s for s in solutions if np.all(s >= lim.lower) and np.all(s <= lim.upper)]
        if not inside:
            raise SetupError(f"task.start: target '{name}' is Cartesian and the robot's IK gives no configuration "
                             "for it within the joint ranges; start from a joint-space target")
        return inside[0]

    # -- planning -----------------------------------------------------------

    def _sensed(self, name: str) -> np.ndarray | None:
        """Where the sensor of a sensor-driven target last saw it (base frame), if it did."""
        spec = self._specs[name]
        reading = self.observations.get(spec.sensor, {})
        pos = reading.get("target_position")
        return None if pos is None else np.asarray(pos, float)

    def _plan(self, t: float, q: np.ndarray, qd: np.ndarray, names: list[str]) -> Plan | None:
        for name in names:  # sensor-driven targets take their latest sensed position
            if self._specs[name].sensor:
                pos = self._sensed(name)
                if pos is None:
                    self.safety.trip(t, q, "plan", f"target '{name}': sensor '{self._specs[name].sensor}' "
                                     "has not seen it")
                    return None
                pose = np.eye(4)
                pose[:3, 3] = pos
                self.targets[name] = Target(name, pose=pose, position_only=True)
        request = PlanRequest(t, q.copy(), qd.copy(), [self.targets[n] for n in names], self.robot)
        try:
            plan = self.planner.plan(request)
        except PlanningError as exc:
            self.safety.trip(t, q, "plan", f"planner failed: {exc}")
            return None
        problem = self._limit_problem(plan) or self._action_problem(plan)
        if problem:
            self.safety.trip(t, q, "plan", f"{problem}; not executed")
            return None
        self._check_box(t, plan)
        return self._accept(plan)

    def _check_box(self, t: float, plan: Plan) -> None:
        """The keep-in box is watched, not planned around: say before moving where a plan will leave it."""
        if not self.safety.watches_box:
            return
        ts = np.arange(0.0, plan.trajectory.duration + 1e-9, 0.005)
        samples = plan.trajectory.sample(ts)[0]
        hand = (self._to_world(samples[:, :3]) if self.planner.space == "cartesian"
                else self.robot.ee_world(samples))
        found = self.safety.box_exit(hand)
        if found is not None:
            k, a, side, bound = found
            self.plan_warnings.append({"t": round(t, 6), "at_s": round(t + float(ts[k]), 3), "message": (
                f"the plan made at t={t:.3f}s takes the hand out of the keep-in box ({AXES[a]} {side} {bound:g}) "
                f"at t={t + ts[k]:.3f}s: the safety layer will stop the robot there; move the target or the box")})

    @staticmethod
    def _action_problem(plan: Plan) -> str | None:
        bad = sorted({kind for _, kind, _ in plan.actions if kind not in SCENE_ACTIONS})
        return f"plan action(s) {bad} unknown; known: {', '.join(SCENE_ACTIONS)}" if bad else None

    def _limit_problem(self, plan: Plan) -> str | None:
        """What joint limit a joint-space plan breaks, if any (Cartesian plans are mapped by the controller)."""
        if self.planner.space == "cartesian":
            return None
        lim = self.robot.model.limits
        ts = np.arange(0.0, plan.trajectory.duration + 1e-9, 0.005)
        qs, qds, _ = plan.trajectory.sample(ts)
        bad_q = (qs < lim.lower - 1e-9) | (qs > lim.upper + 1e-9)
        bad_v = np.abs(qds) > lim.velocity
        if not (bad_q.any() or bad_v.any()):
            return None
        what = "position" if bad_q.any() else "velocity"
        k, j = np.argwhere(bad_q if bad_q.any() else bad_v)[0]
        if what == "position":
            value, limit, unit = qs[k, j], (lim.lower[j] if qs[k, j] < lim.lower[j] else lim.upper[j]), "°"
        else:
            value, limit, unit = abs(qds[k, j]), lim.velocity[j], " °/s"
        return (f"planned trajectory breaks the {what} limit of {self.robot.model.joint_names[j]} at t+{ts[k]:.3f}s "
                f"({np.degrees(value):.1f}{unit}, limit {np.degrees(limit):.1f}{unit})")

    def plan_for_controller(self, t: float, q: np.ndarray, qd: np.ndarray, targets: list[Target]) -> Plan:
        """A plan a controller asks for (e.g. a keypad's replay); it follows the trajectory itself.

        Checked against the joint limits, logged and listed in the summary like the runner's own plans.
        Raises :class:`PlanningError` with the reason when there is none.
        """
        plan = self.planner.plan(PlanRequest(t, q.copy(), qd.copy(), targets, self.robot))
        problem = self._limit_problem(plan) or self._action_problem(plan)
        if problem:
            raise PlanningError(problem)
        k0 = int(round(t / self.schedule.control_dt))
        x = plan.trajectory.sample(np.arange(0.0, plan.trajectory.duration + self.schedule.control_dt,
                                             self.schedule.control_dt))[0]
        self._announce(k0, self._accept(plan), x)
        return plan

    def note(self, t: float, text: str) -> None:
        """A plugin's message for people (an HMI display line): kept in the summary and the log."""
        self.notes.append({"t": round(t, 6), "text": text})
        if self.log:
            self.log.event(t, text, level="INFO")

    def _accept(self, plan: Plan) -> Plan:
        for key, value in plan.diagnostics.items():  # residual-like figures: keep the worst over replans
            self.diag[key] = max(self.diag.get(key, -math.inf), value)
        return plan

    # -- the loop -----------------------------------------------------------

    def run(self) -> RunResult:
        """Build, run and finish; outputs are complete files or none."""
        self.log = None
        self._threads: SensorThreads | None = None
        try:
            return self._run()
        except BaseException:
            if self.log is not None:
                self.log.discard()
            raise
        finally:
            if self._threads is not None:
                self._threads.close()

    def _run(self) -> RunResult:
        t_setup = time.perf_counter()
        self.build()
        sc, sch, robot = self.sc, self.schedule, self.robot
        n, dof = sch.steps, robot.model.dof
        # q, qd, tau of a step sit side by side: the safety layer checks that row in place
        packed = np.zeros((n, 3 * dof))
        self.trace = trace = Trace(np.arange(n) * sch.control_dt, packed[:, :dof], packed[:, dof : 2 * dof],
                                   packed[:, 2 * dof :], np.zeros((n, dof)), np.zeros((n, dof)),
                                   tau_h=np.zeros((n, dof)) if self.patient is not None else None)
        self.log = log = self._open_log()
        self.diag: dict[str, float] = {}
        self.fired: list[dict] = []
        self._actions: list[tuple[int, str, str]] = []
        self.plans: list[dict] = []
        self.reaches: list[Reach] = []

        q0 = self.start_q()
        try:
            self.backend.reset(q0)
        except BackendFaultError as exc:
            raise SetupError(f"backend '{sc.backend.type}': {exc}") from exc
        if hasattr(self.robot, "passive_state"):  # parallel mechanisms: assemble the passive joints too
            self.backend.set_joints(self.robot.passive_state(q0))
        cart = self.planner.space == "cartesian"
        start = self.robot.fk(q0)[:3, 3] if cart else q0  # Cartesian references are in the robot base frame
        self._ref = (np.tile(start, (n + 1, 1)), np.zeros((n + 1, len(start))), np.zeros((n + 1, len(start))))
        self.reference = tuple(r[:n] for r in self._ref)  # views: replans show up here
        if cart:
            trace.x, trace.x_ref = np.zeros((n, 3)), self.reference[0]
            trace.q_ref[:] = q0  # filled from the controller's own joint reference, when it has one
        else:
            trace.q_ref, trace.qd_ref = self.reference[0], self.reference[1]
        self.goal = start.copy()
        self.goal_at = np.tile(start, (n, 1))
        self._install(0, self._plan(0.0, q0, np.zeros(dof), sc.task.order()))
        if self.safety.tripped and self.limit_sources.by_joint:  # refused before it runs, not stopped at t=0
            raise SetupError(f"{self.safety.events[0].message.split(': ', 1)[1].rsplit(';', 1)[0]} "
                             "(joint limits narrowed by the patient's profile or the safety envelope)")
        if log:  # drawn after the first plan: some planners' drawings (a throw's parabola) come from it
            for name, points in self.planner.visuals().items():
                log.points(f"world/planner/{name}", self._to_world(points), (120, 120, 200), 0.003)
        self._timed = sorted((round(e.at / sch.control_dt), i) for i, e in enumerate(sc.task.events)
                             if e.at is not None)
        self._waiting = [i for i, e in enumerate(sc.task.events) if e.reached is not None]
        # 'moved' events: [position last planned for, candidate new position, readings it has held]
        self._watch = {i: [None, None, 0] for i, e in enumerate(sc.task.events) if e.moved is not None}
        self._next_reach, self._stop_at = 0, n
        ramp_steps = int(round(sc.safety.ramp_out_s / sch.control_dt))
        self._ramp_steps, self._ramp_out_at = ramp_steps, (n - ramp_steps if ramp_steps else None)
        self.acted: list[dict] = []
        self._sensor_due = [0] * len(self.sensors)
        if self.backend.realtime and any(s.blocking for s in self.sensors.values()):
            self._threads = SensorThreads([name for name, s in self.sensors.items() if s.blocking],
                                          prepare=encode_images if log else None)

        # the hot loop: one integer comparison a step decides whether anything besides control is due
        ref_q, ref_qd, ref_qdd = self._ref
        state, compute, check = self.backend.state, self.controller.compute, self.safety.check_row
        command, step, contacts = self.backend.command, self.backend.step, self.backend.contacts
        concat, dt, sub = np.concatenate, sch.control_dt, sch.substeps
        log_every = sch.log_every
        next_log = 0 if log else -1
        deferred_log = bool(log) and self.backend.realtime
        if deferred_log:
            log.deferred = True
        bar = tqdm(total=n, unit="step", delay=1.0, disable=not self.progress, leave=False)
        # everything built so far lives for the whole run: frozen, the collector no longer walks it in the loop
        gc.collect()
        gc.freeze()
        safety, stop_after = self.safety, sc.safety.stop_after_s
        tx, tqr, controller, ee = trace.x, trace.q_ref, self.controller, self._ee_world
        own_ref = self.controller.own_reference
        if own_ref:  # the controller's own reference is what it tracked; record that
            trace.q_ref = tqr = np.zeros((n, dof))
            trace.qd_ref = np.zeros((n, dof))
        person = self.patient.torque if self.patient is not None else None
        late = int(round(self.patient.delay_s / dt)) if person else 0  # the person sees the cue this many steps late
        push, tau_h, hand_force, goal_at = self.backend.external_torque, trace.tau_h, self.hand_force, self.goal_at
        contact_steps, due, k = 0, 0, 0
        t_loop = time.perf_counter()
        for k in range(n):
            t = k * dt
            _, q, qd = state()
            if k >= due:
                due = self._due_work(k, t, q, qd)
                if due < 0:
                    break
            row = packed[k]
            try:
                concat((q, qd, compute(t, q, qd, ref_q[k], ref_qd[k], ref_qdd[k])), out=row)
            except Exception as exc:  # a crashing controller must still leave the robot held
                safety.trip(t, q, "plugin-error", f"controller raised {type(exc).__name__}: {exc}")
                compute = _idle(dof)  # once tripped, the safety layer drives; don't call it again
                concat((q, qd, np.zeros(dof)), out=row)
            if person is not None:
                tau_h[k] = person(t, q, qd, goal_at[max(0, k - late)])
                if hand_force is not None:
                    safety.check_force(t, q, hand_force(q, tau_h[k]))
            tau = check(t, row)
            if cart:
                tx[k] = ee(q)  # world frame here; moved into the base frame once, at the end
                if controller.joint_reference is not None:
                    tqr[k] = controller.joint_reference
            elif own_ref:
                tqr[k] = controller.joint_reference
            try:
                command(tau)
                if person is not None:
                    push(tau_h[k])
                step(sub)
            except BackendFaultError as exc:  # the robot can't be driven any more: stop here, logs complete
                safety.trip(t, q, "backend", str(exc))
                k += 1
                break
            if contacts():
                contact_steps += 1
            if k == next_log:
                next_log += log_every
                log.record(t, self.backend.body_poses(), self._ee_world(q))
                if log.pending >= LOG_FLUSH_SAMPLES:
                    self._flush_log(k + 1)
            if deferred_log and log.queued:  # wall-clock run: one entity's columns a tick
                log.send_one()
            if k % 1000 == 999:
                bar.update(1000)
            if safety.tripped_at is not None and t + dt - safety.tripped_at >= stop_after - 1e-9:
                k += 1
                break
        else:
            k = n
        wall = time.perf_counter() - t_loop
        gc.unfreeze()
        if self._threads is not None:  # no reading in flight while the run is summed up
            self._threads.close()
            self.diag.update({f"sensor_overruns_{name}": float(self._threads.overruns[name])
                              for name in self.sensors if name in self._threads})
        bar.close()
        if cart:
            base = self.robot.model.base_pose
            trace.x[:k] = (trace.x[:k] - base[:3, 3]) @ base[:3, :3]
            if controller.joint_reference is None:  # a controller without a joint reference: no joint tracking
                trace.q_ref[:] = np.nan
        if log:
            self._flush_log(k)
            if self.robot.model.dof == 3 and k:
                log.line("joint_space/executed", np.degrees(trace.q[:k:10]), (250, 180, 40), 0.3)
        return self._finish(trace.trimmed(k), wall, t_loop - t_setup, contact_steps)

    def _flush_log(self, upto: int) -> None:
        """Send the joint series recorded since the last flush, at the log rate, and the buffered poses."""
        tr, every = self.trace, self.schedule.log_every
        sel = slice(getattr(self, "_logged_upto", 0), upto, every)
        self.log.joint_series(tr.t[sel], tr.q[sel], tr.qd[sel], tr.tau[sel], tr.q_ref[sel])
        self.log.flush()
        self._logged_upto = sel.start + len(tr.t[sel]) * every

    def _due_work(self, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> int:
        """Events, 'reached' checks and sensors due at step ``k``; the next step anything is due, -1 to stop."""
        sc, sch = self.sc, self.schedule
        try:
            while self._timed and self._timed[0][0] <= k:
                self._fire(self._timed.pop(0)[1], k, t, q, qd)
            while self._actions and self._actions[0][0] <= k:
                _, kind, obj = self._actions.pop(0)
                getattr(self.backend, kind)(obj)  # 'release' / 'grasp'
                self.acted.append({"t": round(t, 6), "action": kind, "object": obj})
                if self.log:
                    self.log.event(t, f"{kind} {obj}", level="INFO")
            if self._waiting and k >= self._next_reach:
                self._next_reach = k + sch.reach_every
                ee = self.robot.fk(q)[:3, 3]  # base frame, as target poses are
                for i in list(self._waiting):
                    ev = sc.task.events[i]
                    if np.linalg.norm(ee - self.targets[ev.reached].pose[:3, 3]) <= ev.tolerance_m:
                        self._waiting.remove(i)
                        self._fire(i, k, t, q, qd)
            if self._ramp_out_at is not None and k >= self._ramp_out_at:
                self.safety.begin_ramp_out(t, q)
                self._ramp_out_at = None
            if k >= self._stop_at:
                return -1
            for j, ((name, sensor), every) in enumerate(zip(self.sensors.items(), sch.sensor_every)):
                if k >= self._sensor_due[j]:
                    self._sensor_due[j] = k + every
                    if self._threads is not None and name in self._threads:
                        self._threads.start(name, sensor, t, q, qd, self.backend)
                    else:
                        self._take(name, t, sensor.read(t, q, qd, self.backend), k, t, q, qd)
            if self._threads is not None:
                for name, t_read, reading in self._threads.finished():
                    self._take(name, t_read, reading, k, t, q, qd)
        except Exception as exc:
            self.safety.trip(t, q, "plugin-error", f"{type(exc).__name__} during events/sensors: {exc}")
        upcoming = [self._stop_at, *self._sensor_due]
        if self._ramp_out_at is not None:
            upcoming.append(self._ramp_out_at)
        if self._timed:
            upcoming.append(self._timed[0][0])
        if self._actions:
            upcoming.append(self._actions[0][0])
        if self._waiting:
            upcoming.append(self._next_reach)
        if self._threads is not None and self._threads.busy:
            upcoming.append(k + 1)  # a sensor thread's reading is taken at the first tick after it is done
        return max(k + 1, min(upcoming))

    def _take(self, name: str, t_read: float, reading: dict, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """A sensor's reading (started at ``t_read``) into the observations and the log; 'moved' events."""
        self.observations[name] = reading
        if self.log:
            self.log.sensor(t_read, name, reading)
            if reading.get("target_position") is not None:
                self.log.points(f"world/sensed/{name}", self._to_world(reading["target_position"]),
                                (40, 220, 40), 0.02, t_read)
        self._check_moved(name, k, t, q, qd)

    def _check_moved(self, sensor: str, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """Fire 'moved' events whose target this sensor sees somewhere new, once it has settled there."""
        for i, state in self._watch.items():
            ev = self.sc.task.events[i]
            if self._specs[ev.moved].sensor != sensor:
                continue
            pos = self._sensed(ev.moved)
            planned, candidate, held = state
            if pos is None or (planned is not None and np.linalg.norm(pos - planned) <= ev.tolerance_m):
                state[1], state[2] = None, 0
                continue
            if candidate is not None and np.linalg.norm(pos - candidate) <= ev.tolerance_m:
                state[2] = held + 1
            else:
                state[1], state[2] = pos, 1
            if state[2] >= ev.settle:
                state[0], state[1], state[2] = pos, None, 0
                self._fire(i, k, t, q, qd)

    def _install(self, k0: int, plan: Plan | None) -> None:
        """Write a plan's reference into the step arrays from step ``k0`` on."""
        if plan is None:
            return
        ref, ref_d, ref_dd = self._ref
        dt = self.schedule.control_dt
        x, xd, xdd = plan.trajectory.sample(np.arange(len(ref) - k0) * dt)
        ref[k0:], ref_d[k0:], ref_dd[k0:] = x, xd, xdd
        self.goal = x[-1].copy()
        self._announce(k0, plan, x)

    def _announce(self, k0: int, plan: Plan, x: np.ndarray) -> None:
        """List a plan in the summary and draw it (``x``: its reference sampled at the control rate)."""
        cart = self.planner.space == "cartesian"
        dt = self.schedule.control_dt
        # scene actions of the plan (a throw's release): they replace those of the plan before
        self._actions = sorted([a for a in self._actions if a[0] < k0]
                               + [(k0 + int(round(at / dt)), kind, obj) for at, kind, obj in plan.actions])
        self._add_reaches(k0, plan, x)
        way = plan.waypoints
        entry = {"t": round(k0 * dt, 6), "duration_s": plan.trajectory.duration}
        if way is not None:
            entry["waypoints_m" if cart else "waypoints_deg"] = np.round(way if cart else np.degrees(way), 6).tolist()
        self.plans.append({**entry, **{k: v for k, v in plan.diagnostics.items() if isinstance(v, (int, float))},
                           **plan.details})
        if self.log:
            model = self.robot.model
            if cart:
                base = model.base_pose
                to_world = lambda p: np.asarray(p).reshape(-1, 3) @ base[:3, :3].T + base[:3, 3]  # noqa: E731
                path, way_w = to_world(x[:: self.schedule.log_every]), to_world(way if way is not None else [])
            else:
                path = self.robot.ee_world(x[:: self.schedule.log_every])
                way_w = self.robot.ee_world(way) if way is not None else np.zeros((0, 3))
                if model.dof == 3:
                    self.log.line("joint_space/plan", np.degrees(x[:: self.schedule.log_every]), (60, 160, 255), 0.3,
                                  k0 * dt)
                    if way is not None:
                        self.log.points("joint_space/task_points", np.degrees(way), (60, 160, 255), 1.0, k0 * dt)
            self.log.plan(k0 * dt, path, way_w)

    def _add_reaches(self, k0: int, plan: Plan, x: np.ndarray) -> None:
        """The plan's movements for the outcome measures: one per stretch between waypoints, or the whole plan."""
        dt, cart = self.schedule.control_dt, self.planner.space == "cartesian"
        hand = (lambda p: np.asarray(p, float)) if cart else (lambda q: self.robot.fk(q)[:3, 3])  # noqa: E731
        self.reaches = [r for r in self.reaches if r.k0 < k0]  # a replan cuts the movement under way
        if self.reaches:
            self.reaches[-1].k1 = min(self.reaches[-1].k1, k0)
        times, way = plan.waypoint_times, plan.waypoints
        n = self.schedule.steps
        if times is not None and way is not None and len(times) == len(way) > 1:
            starts = [k0 + int(round(t / dt)) for t in times]
            new = [Reach(starts[i - 1], starts[i], hand(way[i]), np.asarray(way[i], float)) for i in range(1, len(way))]
            new[-1].k1 = n  # the last one may settle after its end
        else:
            new = [Reach(k0, n, hand(x[-1]), x[-1].copy())]
        for r in new:  # what a (simulated) person aims for, step by step
            self.goal_at[r.k0 :] = r.target
        self.reaches += new

    def _ee_world(self, q: np.ndarray) -> np.ndarray:
        ee = self.backend.ee_position()
        if ee is not None:
            return ee
        return self.robot.ee_world(q[None])[0]

    def _fire(self, i: int, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        ev = self.sc.task.events[i]
        trigger = f"at {ev.at}" if ev.at is not None else (
            f"reached {ev.reached}" if ev.reached is not None else f"{ev.moved} moved")
        self.fired.append({"event": i, "t": round(t, 6), "action": ev.action, "trigger": trigger})
        if self.log:
            self.log.event(t, f"event {i}: {trigger} -> {ev.action}", level="INFO")
        if ev.action == "stop":  # with a ramp-out, the robot is eased into holding first
            self._stop_at = min(self._stop_at, k + self._ramp_steps)
            if self._ramp_steps:
                self._ramp_out_at = k
        elif ev.action == "move":
            self.backend.move_object(ev.object, np.asarray(ev.position, float))
        else:
            self._install(k, self._plan(t, q, qd, ev.sequence or self.sc.task.order()))

    def _open_log(self) -> RerunLog | None:
        if self.out_dir is None or not self.sc.logging.rrd:
            return None
        self.out_dir.mkdir(parents=True, exist_ok=True)
        log = RerunLog(self.out_dir / "run.rrd", self.sc.logging.application_id, self.robot.model.joint_names,
                       spawn=self.spawn)
        log.scene(self.backend.visual_geoms())
        named = [(n, t) for n, t in self.targets.items() if t.pose is not None]
        pts = np.array([self.robot.model.base_pose[:3, :3] @ t.pose[:3, 3] + self.robot.model.base_pose[:3, 3]
                        for _, t in named]).reshape(-1, 3)
        log.targets(0.0, [n for n, _ in named], pts)
        if self.robot.model.dof == 3:  # a joint space one can look at: degrees on three axes
            for name, points in self.planner.joint_space_visuals().items():
                log.points(f"joint_space/{name}", np.degrees(points), (200, 80, 80), 0.4)
        return log

    def _to_world(self, points: np.ndarray) -> np.ndarray:
        base = self.robot.model.base_pose
        return np.asarray(points, float).reshape(-1, 3) @ base[:3, :3].T + base[:3, 3]

    def _finish(self, trace: Trace, wall: float, setup: float, contact_steps: int) -> RunResult:
        """Metrics, verdicts, the summary; the log and summary written whole."""
        if robot_side := self.backend.interventions():
            self.safety.interventions = sorted(self.safety.interventions + robot_side, key=lambda e: e.t)
        metrics, per_joint = collect_metrics(self, trace, wall, setup, contact_steps)
        if self.log:
            levels = {"ramp-in": "INFO", "ramp-out": "INFO", "torque-clip": "WARN", "stale-command": "WARN"}
            for ev in self.safety.interventions:
                self.log.event(ev.t, f"SAFETY {ev.rule}: {ev.message}", level=levels.get(ev.rule, "ERROR"))
            series = {**self.backend.series(), **getattr(self.controller, "series", dict)(),
                      **(self.patient.series() if self.patient is not None else {}),
                      **outcome_series(trace.t, self.outcome_details, self.schedule.log_every)}
            for path, (t, values) in series.items():
                self.log.series(path, np.asarray(t, float), np.asarray(values, float))
        summary = build_summary(self, metrics, per_joint)
        if self.out_dir is not None:
            if self.log:
                self.log.close()
                summary["outputs"] = {"rrd": "run.rrd"}
            summary.setdefault("outputs", {})["scenario"] = SNAPSHOT
            atomic_write_text(self.out_dir / SNAPSHOT, f"# {self.loaded.path} as this run used it (extends merged, "
                              "profile inlined, --set applied); `rehabkit replay` reads it\n"
                              + yaml.safe_dump(self.loaded.source.data, sort_keys=False))
            atomic_write_json(self.out_dir / "summary.json", summary)
        self.backend.close()
        return RunResult(summary, trace, self.out_dir)
