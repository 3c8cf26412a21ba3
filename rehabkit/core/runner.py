"""Build a scenario's plugins and run its loop.

The data flow, in order: validated scenario → plugin instances (robot first;
the others get it in their context) → plan at start → fixed-step loop
(events → sensors → controller → safety layer → backend) → metrics →
``summary.json`` with the ``expect:`` verdicts, and the Rerun log alongside.
The loop calls plugin objects directly; pluggy is only used to find them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

import rehabkit
from rehabkit.core.interfaces import Context, Plan, PlanningError, PlanRequest, Target
from rehabkit.core.io import atomic_write_json
from rehabkit.core.log import RerunLog
from rehabkit.core.metrics import Trace, evaluate, tracking_metrics
from rehabkit.core.plugins import PluginRegistry, default_registry
from rehabkit.core.safety import SafetyLayer
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.targets import resolve_targets

REACH_CHECK_HZ = 100.0  # 'reached' events are tested at this rate, not every control step


@dataclass
class RunResult:
    """What a run produced.

    Attributes:
        summary: The content of ``summary.json``.
        trace: Control-rate arrays of the run.
        out_dir: Where files were written (``None`` when nothing was written).
    """

    summary: dict[str, Any]
    trace: Trace
    out_dir: Path | None

    @property
    def passed(self) -> bool:
        return bool(self.summary["passed"])

    @property
    def metrics(self) -> dict[str, float]:
        return self.summary["metrics"]

    @property
    def failures(self) -> list[dict]:
        return [e for e in self.summary["expectations"] if not e["passed"]]


class SetupError(RuntimeError):
    """The scenario is valid but its plugins can't be put together (message says why)."""


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

    # -- construction -------------------------------------------------------

    def _make(self, kind: str, config, ctx: Context):
        info = self.registry.get(kind, config.type)
        try:
            return info.factory(config, ctx)
        except (ValueError, PlanningError) as exc:
            raise SetupError(f"{kind} '{config.type}': {exc}") from exc

    def build(self) -> None:
        sc = self.sc
        ctx = Context(self.loaded.directory, np.random.default_rng(sc.seed), 1.0 / sc.rates.control_hz, world=sc.world)
        self.robot = self._make("robot", sc.robot, ctx)
        ctx.robot = self.robot
        self.backend = self._make("backend", sc.backend, ctx)
        self.planner = self._make("planner", sc.planner, ctx)
        self.controller = self._make("controller", sc.controller, ctx)
        self.sensors = {name: self._make("sensor", cfg, ctx) for name, cfg in sc.sensors.items()}
        self.safety = SafetyLayer(self.robot.model, sc.safety)
        try:
            self.targets = resolve_targets(sc.task, self.robot)
        except PlanningError as exc:
            raise SetupError(f"task: {exc}") from exc
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
        q = self.targets[name].q
        if q is None:
            raise SetupError(f"task.start: target '{name}' is Cartesian; the start must be a joint-space target")
        return q.copy()

    # -- planning -----------------------------------------------------------

    def _plan(self, t: float, q: np.ndarray, qd: np.ndarray, names: list[str]) -> Plan | None:
        request = PlanRequest(t, q.copy(), qd.copy(), [self.targets[n] for n in names], self.robot)
        try:
            plan = self.planner.plan(request)
        except PlanningError as exc:
            self.safety.trip(t, q, "plan", f"planner failed: {exc}")
            return None
        lim = self.robot.model.limits
        ts = np.arange(0.0, plan.trajectory.duration + 1e-9, 0.005)
        qs, qds, _ = plan.trajectory.sample(ts)
        bad_q = (qs < lim.lower) | (qs > lim.upper)
        bad_v = np.abs(qds) > lim.velocity
        if bad_q.any() or bad_v.any():
            what = "position" if bad_q.any() else "velocity"
            k, j = np.argwhere(bad_q if bad_q.any() else bad_v)[0]
            self.safety.trip(t, q, "plan", f"planned trajectory breaks the {what} limit of "
                             f"{self.robot.model.joint_names[j]} at t+{ts[k]:.3f}s; not executed")
            return None
        for key, value in plan.diagnostics.items():  # residual-like figures: keep the worst over replans
            self.diag[key] = max(self.diag.get(key, -math.inf), value)
        return plan

    # -- the loop -----------------------------------------------------------

    def run(self) -> RunResult:
        t_setup = time.perf_counter()
        self.build()
        sc, sch, robot = self.sc, self.schedule, self.robot
        n, dof = sch.steps, robot.model.dof
        trace = Trace(np.arange(n) * sch.control_dt, *(np.zeros((n, dof)) for _ in range(5)))
        log = self._open_log()
        self.diag: dict[str, float] = {}

        q0 = self.start_q()
        self.backend.reset(q0)
        ref_q, ref_qd, ref_qdd = (np.tile(q0, (n + 1, 1)), np.zeros((n + 1, dof)), np.zeros((n + 1, dof)))
        goal_q = q0.copy()
        ticks = np.arange(n + 1) * sch.control_dt

        def install(k0: int, plan: Plan | None) -> None:
            nonlocal goal_q
            if plan is None:
                return
            q, qd, qdd = plan.trajectory.sample(ticks[k0:] - ticks[k0])
            ref_q[k0:], ref_qd[k0:], ref_qdd[k0:] = q, qd, qdd
            goal_q = q[-1].copy()
            if log:
                log.plan(ticks[k0], robot.model.ee_positions_world(q[:: max(1, sch.log_every)]),
                         robot.model.ee_positions_world(plan.waypoints) if plan.waypoints is not None
                         else np.zeros((0, 3)))

        install(0, self._plan(0.0, q0, np.zeros(dof), sc.task.order()))
        timed = sorted((round(e.at / sch.control_dt), i) for i, e in enumerate(sc.task.events) if e.at is not None)
        waiting = [i for i, e in enumerate(sc.task.events) if e.reached is not None]
        fired: list[dict] = []
        contact_steps, stop_at = 0, n
        sensors = list(self.sensors.items())
        controller, safety, backend = self.controller, self.safety, self.backend

        bar = tqdm(total=n, unit="step", delay=1.0, disable=not self.progress, leave=False)
        t_loop = time.perf_counter()
        k = 0
        for k in range(n):
            t = k * sch.control_dt
            _, q, qd = backend.state()
            while timed and timed[0][0] <= k:
                i = timed.pop(0)[1]
                stop_at = self._fire(i, k, t, q, qd, install, fired, log, stop_at)
            if waiting and k % sch.reach_every == 0:
                ee = robot.model.ee_pose(q, self._pin_data)[:3, 3]  # base frame, as target poses are
                for i in list(waiting):
                    ev = sc.task.events[i]
                    if np.linalg.norm(ee - self.targets[ev.reached].pose[:3, 3]) <= ev.tolerance_m:
                        waiting.remove(i)
                        stop_at = self._fire(i, k, t, q, qd, install, fired, log, stop_at)
            if k >= stop_at:
                break
            for (name, sensor), every in zip(sensors, sch.sensor_every):
                if k % every == 0:
                    reading = sensor.read(t, q, qd, backend)
                    self.observations[name] = reading
                    if log:
                        log.sensor(t, name, reading)
            tau = controller.compute(t, q, qd, ref_q[k], ref_qd[k], ref_qdd[k])
            tau = safety.filter(t, q, qd, tau)
            trace.q[k], trace.qd[k], trace.tau[k], trace.q_ref[k], trace.qd_ref[k] = q, qd, tau, ref_q[k], ref_qd[k]
            if log and k % sch.log_every == 0:
                log.record(t, backend.body_poses(), q, qd, tau, ref_q[k], self._ee_world(q))
            backend.command(tau)
            backend.step(sch.substeps)
            if backend.contacts():
                contact_steps += 1
            if safety.tripped_at is not None and t - safety.tripped_at >= sc.safety.stop_after_s:
                k += 1
                break
            if k % 250 == 249:
                bar.update(250)
        else:
            k = n
        wall = time.perf_counter() - t_loop
        bar.close()
        trace = trace.trimmed(k)
        return self._finish(trace, goal_q, wall, t_loop - t_setup, contact_steps, fired, log)

    @property
    def _pin_data(self):
        if not hasattr(self, "_pd"):
            self._pd = self.robot.model.new_pin_data()
        return self._pd

    def _ee_world(self, q: np.ndarray) -> np.ndarray:
        base = self.robot.model.base_pose
        return base[:3, :3] @ self.robot.model.ee_pose(q, self._pin_data)[:3, 3] + base[:3, 3]

    def _fire(self, i, k, t, q, qd, install, fired, log, stop_at) -> int:
        ev = self.sc.task.events[i]
        fired.append({"event": i, "t": round(t, 6), "action": ev.action,
                      "trigger": f"at {ev.at}" if ev.at is not None else f"reached {ev.reached}"})
        if log:
            log.event(t, f"event {i}: {fired[-1]['trigger']} → {ev.action}", level="INFO")
        if ev.action == "stop":
            return k
        install(k, self._plan(t, q, qd, ev.sequence or self.sc.task.order()))
        return stop_at

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
        return log

    def _finish(self, trace, goal_q, wall, setup, contact_steps, fired, log) -> RunResult:
        sc = self.sc
        sim_time = len(trace.t) * self.schedule.control_dt
        metrics, per_joint = tracking_metrics(trace, self.robot.model, goal_q)
        metrics.update(self.diag)
        metrics.update({
            "sim_time_s": sim_time, "wall_time_s": wall, "setup_time_s": setup,
            "real_time_factor": sim_time / wall if wall > 0 else float("inf"),
            "contact_steps": contact_steps, "safety_events": len(self.safety.events),
            "torque_saturation_steps": self.safety.saturated_steps,
        })
        for ev in self.safety.events:
            if log:
                log.event(ev.t, f"SAFETY {ev.rule}: {ev.message}", level="ERROR")
        verdicts = evaluate(sc.expect, metrics)
        summary = {
            "scenario": str(self.loaded.path), "name": sc.name or self.loaded.path.stem,
            "rehabkit_version": rehabkit.__version__, "seed": sc.seed,
            "plugins": self._plugin_versions(),
            "passed": all(v["passed"] for v in verdicts) and not self._unexpected_trip(),
            "sim_time_s": sim_time, "wall_time_s": wall, "real_time_factor": metrics["real_time_factor"],
            "metrics": metrics, "per_joint": per_joint, "expectations": verdicts,
            "safety": {"tripped": self.safety.tripped, "events": [e.as_dict() for e in self.safety.events]},
            "events": fired,
        }
        if self.out_dir is not None:
            if log:
                log.close()
                summary["outputs"] = {"rrd": "run.rrd"}
            atomic_write_json(self.out_dir / "summary.json", summary)
        self.backend.close()
        return RunResult(summary, trace, self.out_dir)

    def _unexpected_trip(self) -> bool:
        """A safety stop fails the run unless the scenario's expectations are about safety events."""
        return self.safety.tripped and "safety_events" not in self.sc.expect

    def _plugin_versions(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        sc = self.sc
        for kind, cfg in (("robot", sc.robot), ("backend", sc.backend), ("planner", sc.planner),
                          ("controller", sc.controller)):
            p = self.registry.get(kind, cfg.type).provider
            out[kind] = {"type": cfg.type, "package": p.package, "version": p.version}
        out["sensors"] = {n: {"type": c.type, **vars(self.registry.get("sensor", c.type).provider)}
                          for n, c in sc.sensors.items()}
        return out
