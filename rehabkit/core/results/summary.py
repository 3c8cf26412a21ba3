"""What a run produced: its metrics, the expectations' verdicts and the summary document.

Everything here reads the assembled run (:class:`~rehabkit.core.setup.assembly.Assembly`:
what it was made of) and its :class:`~rehabkit.core.results.record.RunRecord` (what
happened); nothing writes back into either.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rehabkit.core.kinds.metric import MetricCatalogue
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.plugins.lifecycle import Contribution
from rehabkit.core.results.ending import RunEnding
from rehabkit.core.results.metrics import evaluate, tracking_metrics
from rehabkit.core.results.record import RunRecord
from rehabkit.core.results.tracking_causes import tracking_causes
from rehabkit.core.safety.stopping import joint_inertia, stop_figures
from rehabkit.core.setup.assembly import Assembly
from rehabkit.core.version import __version__


@dataclass
class RunResult:
    """What a run produced.

    Attributes:
        summary: The content of ``summary.json``.
        trace: Control-rate arrays of the run.
        out_dir: Where files were written (``None`` when nothing was written).
        refusal: When the task's first plan failed on the scenario as written (a target out of reach, a planner
            setting that does not fit), that failure located in the file; the robot did not move.
    """

    summary: dict[str, Any]
    trace: Trace
    out_dir: Path | None
    refusal: Any = None
    ending: RunEnding | None = None  # how the run ended (None: as completed)

    @property
    def exit_code(self) -> int:
        """The command's exit code for this run: how it ended and whether it passed (``RunEnding.exit_code``)."""
        return (self.ending or RunEnding("completed")).exit_code(self.passed)

    @property
    def passed(self) -> bool:
        return bool(self.summary["passed"])

    @property
    def metrics(self) -> dict[str, float]:
        return self.summary["metrics"]

    @property
    def failures(self) -> list[dict]:
        return [e for e in self.summary["expectations"] if not e["passed"]]


def core_metrics(a: Assembly, r: RunRecord) -> tuple[dict[str, float], dict[str, Any]]:
    """The core's and the plugins' metrics: tracking, plans, timing, contacts, safety."""
    trace = r.trace
    sim_time = len(trace.t) * a.schedule.control_dt
    metrics, per_joint = tracking_metrics(trace, a.robot, a.space.goal(r.goal))
    metrics.update(a.space.metrics(trace))
    metrics.update(r.plan_metrics)
    metrics.update(a.planner.run_metrics(trace))
    metrics.update(a.controller.run_metrics(trace))
    metrics.update(a.backend.run_metrics(trace))
    for sensor in a.sensors.values():
        metrics.update(sensor.run_metrics(trace))
    if a.patient is not None:
        metrics.update(a.patient.run_metrics(trace))
    metrics.update(r.extra_metrics)
    metrics.update({
        "sim_time_s": sim_time, "wall_time_s": r.wall_s, "setup_time_s": r.setup_s,
        "real_time_factor": sim_time / r.wall_s if r.wall_s > 0 else float("inf"),
        "contact_steps": r.contact_steps, "safety_events": len(r.safety.events),
        "torque_saturation_steps": r.safety.saturated_steps,
    })
    metrics.update(stop_metrics(a, trace, r.safety))
    ends = [p["t"] + p["duration_s"] for p in r.plans if "duration_s" in p]
    if ends:  # (the task's time: did the run last until its last plan's end?)
        metrics["plan_end_s"] = float(max(ends))
        metrics["task_complete"] = float(max(ends) <= sim_time + a.schedule.control_dt + 1e-9)  # (reaches: below)
    return metrics, per_joint


def _tracking_why(a: Assembly, r: RunRecord) -> dict[str, Any] | None:
    """Why the worst joint tracked badly, where it did (:func:`tracking_causes`)."""
    trace, safety = r.trace, r.safety
    if not len(trace.t):
        return None
    trip = (safety.tripped_at, safety.events[0].rule) if safety.tripped_at is not None and safety.events else None
    try:
        inertia = joint_inertia(a.robot.model, trace.q[0])
    except Exception:  # noqa: BLE001 (no dynamics model to judge by)
        inertia = None
    return tracking_causes(trace, a.robot.model, trip, r.first_contact, inertia)


def stop_metrics(a: Assembly, trace, safety) -> dict[str, float]:
    """What the run's ``safety`` layer's stop took (the first trip): its category, the time to standstill, the travel
    meanwhile."""
    if safety.tripped_at is None or not len(trace.t):
        return {}
    k0 = int(np.searchsorted(trace.t, safety.tripped_at - 1e-12))
    hand = np.full((len(trace.t), 3), np.nan)
    hand[k0:] = a.robot.fk_batch(trace.q[k0:])[:, :3, 3]  # (the stop's steps only)
    figures = stop_figures(trace.t, trace.q, trace.qd, hand, safety.tripped_at, a.robot.model.revolute)
    category = safety.category
    out = {"stop_category": float(category) if category is not None else math.nan, **figures}
    lim = safety.limits
    out["joints_in_range"] = float(np.all((trace.q[k0:] >= lim.lower) & (trace.q[k0:] <= lim.upper)))
    limit = safety.config.interaction_force_n
    if trace.f_h is not None and limit is not None:
        after = trace.f_h[k0:]
        dt = float(trace.t[1] - trace.t[0]) if len(trace.t) > 1 else 0.0
        out["force_after_trip_peak_n"] = float(after.max()) if len(after) else 0.0
        out["force_above_limit_s"] = float(np.count_nonzero(after > limit) * dt)
    return out


def plugin_versions(a: Assembly) -> dict[str, Any]:
    """Type, package and version of every plugin the run used."""
    sc, registry = a.sc, a.registry
    out: dict[str, Any] = {}
    for kind, cfg in (("robot", sc.robot), ("backend", sc.backend), ("planner", sc.planner),
                      ("controller", sc.controller), ("patient", a.patient_slot.config if a.patient_slot else None)):
        if cfg is None:
            continue
        p = registry.get(kind, cfg.type).provider
        out[kind] = {"type": cfg.type, "package": p.package, "version": p.version}
    out["sensors"] = {n: {"type": c.type, **vars(registry.get("sensor", c.type).provider)}
                      for n, c in sc.sensors.items()}
    return out


def run_inputs(a: Assembly, r: RunRecord) -> dict[str, Any]:
    """Fingerprints of what drove the run besides its plugins, so a replay can tell whether they were the same."""
    rng_state = json.dumps(a.context.rng.bit_generator.state, sort_keys=True, default=str).encode()
    return {"seed": a.sc.seed, "target_timeline": [[f["t"], f["trigger"]] for f in r.fired],
            "sensor_noise": hashlib.sha256(rng_state).hexdigest()[:16],
            **(a.patient.inputs() if a.patient is not None else {})}


def summarize(a: Assembly, r: RunRecord, catalogue: MetricCatalogue, view,
              ending: RunEnding | None = None) -> dict[str, Any]:
    """The summary document: how the run ended, metrics (the core's, the plugins', the extensions'), verdicts,
    safety, events, plans, reports, and the extensions' sections; the interventions and series go to the log.

    A safety stop fails the run unless the scenario's expectations are about safety events. A run cut short
    (``ending.early``: interrupted, a plugin's or the backend's fault) is judged on what it reached, and an expectation
    it met by then is said not reached rather than passed.
    """
    ending = ending or RunEnding("completed")
    sc = a.sc
    interventions = r.interventions
    metrics, per_joint = core_metrics(a, r)
    contributions: list[Contribution] = a.extensions.run_finished(a, r, r.extension_states)
    sections: dict[str, Any] = dict(a.sections)
    for c in contributions:
        metrics.update(c.metrics)
        sections.update(c.sections)
    def series() -> dict[str, tuple]:  # (gathered only for a recording)
        out = {**a.backend.series(), **a.controller.series(), **(a.patient.series() if a.patient is not None else {})}
        for c in contributions:
            out.update(c.series)
        return out

    if metrics.get("reaches") and metrics.get("reaches_completed") == metrics["reaches"]:
        metrics["task_complete"] = 1.0  # (every reach got to its target and stayed: the plan's settling tail cut)
    view.finish(interventions, series)
    metrics = {k: _as_count(v) if catalogue.get(k).unit == "count" else v for k, v in metrics.items()}
    verdicts = evaluate(sc.expect, metrics)
    if ending.early:  # what the run met before it was cut short is not what the scenario asked of the whole run
        for v in verdicts:
            if v["passed"]:
                v.update(passed=False, reason=f"not reached: the run {ending.words} at "
                                              f"{metrics.get('sim_time_s', 0.0):.3f} s of {sc.duration:g} s")
    if r.no_plan is not None and "safety_events" not in sc.expect:  # (unless the scenario expects a stop)
        # a robot that never moved has no tracking error: that passes nothing
        for v in verdicts:
            v.update(passed=False, reason=f"no plan ran ({r.no_plan})")
    unexpected_trip = r.safety.tripped and "safety_events" not in sc.expect
    task = task_section(metrics)
    # an unfinished task fails a run that has verdicts (they would judge what did not happen), as a stop does, unless
    # the scenario says otherwise (a rehearsal of the first seconds: `expect: {task_complete: {eq: 0}}`) or expects a
    # stop (a safety skill: safety_events ≥ 1)
    expects_stop = "safety_events" in sc.expect and not evaluate({"safety_events": sc.expect["safety_events"]},
                                                                  {"safety_events": 0})[0]["passed"]
    unfinished = task is not None and not task["complete"] and bool(sc.expect) and "task_complete" not in sc.expect \
        and not expects_stop  # (no expectations at all: nothing is judged, the TASK line says it all the same)
    return {
        "scenario": str(a.loaded.path), "name": sc.name or a.loaded.path.stem,
        "rehabkit_version": __version__, "seed": sc.seed, "plugins": plugin_versions(a),
        "ended": ending.as_dict(),
        "passed": all(v["passed"] for v in verdicts) and not unexpected_trip and not unfinished and not ending.early,
        "metrics": metrics, "metric_info": catalogue.info(metrics), "per_joint": per_joint, "expectations": verdicts,
        "safety": {"tripped": r.safety.tripped, "events": [e.as_dict() for e in r.safety.events],
                   "interventions": [e.as_dict() for e in interventions],
                   "plan_warnings": r.plan_warnings, "estop_latched": a.backend.latched_estop(),
                   **({"first_contact": r.first_contact} if r.first_contact else {})},
        "inputs": run_inputs(a, r),
        **({"task": task} if task is not None else {}),
        **({"tracking": why} if (why := _tracking_why(a, r)) is not None else {}),
        **sections,
        "events": r.fired, "plans": r.plans, "notes": r.notes, "actions": r.acted,
        "reports": {name: text for name, s in a.sensors.items() if (text := s.report(metrics))},
    }


def task_section(metrics: dict[str, Any]) -> dict[str, Any] | None:
    """Whether the task finished, in summary.json's words: its plan's end against the run's, and its reaches."""
    if "task_complete" not in metrics:
        return None
    out = {"complete": bool(metrics["task_complete"]), "plan_end_s": metrics["plan_end_s"],
           "run_s": metrics["sim_time_s"]}
    if "reaches" in metrics:
        out.update(reaches=metrics["reaches"], reaches_completed=metrics.get("reaches_completed", 0))
        if "reaches_planned" in metrics:  # (a run cut short began fewer than its plans hold)
            out["reaches_planned"] = metrics["reaches_planned"]
    return out


def _as_count(value: Any) -> Any:
    """A count as the integer it is (plugins often report counts as floats)."""
    return int(value) if isinstance(value, float) and value.is_integer() else value
