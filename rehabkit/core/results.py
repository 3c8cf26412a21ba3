"""What a run produced: its metrics, the expectations' verdicts and the summary document."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import rehabkit
from rehabkit.core.metrics import Trace, cartesian_metrics, evaluate, tracking_metrics
from rehabkit.rehab.run_outcomes import run_outcomes

if TYPE_CHECKING:
    from rehabkit.core.runner import Runner


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


def collect_metrics(run: Runner, trace: Trace, wall: float, setup: float, contact_steps: int
                    ) -> tuple[dict[str, float], dict[str, Any]]:
    """Every metric of a run: tracking, the planner's and sensors' own, timing, contacts, safety."""
    sim_time = len(trace.t) * run.schedule.control_dt
    cart = run.planner.space == "cartesian"
    own = run.controller.own_reference  # the runner's goal is not where such a controller went
    metrics, per_joint = tracking_metrics(trace, run.robot, None if cart or own else run.goal)
    if cart:
        metrics.update(cartesian_metrics(trace))
    metrics.update(run.diag)
    metrics.update(run.planner.run_metrics(trace))
    metrics.update(run.controller.run_metrics(trace))
    metrics.update(run.backend.run_metrics())
    for sensor in run.sensors.values():
        metrics.update(sensor.run_metrics(trace))
    if run.patient is not None:
        metrics.update(run.patient.run_metrics(trace))
    breaches = sum(e.rule not in ("ramp-in", "ramp-out") for e in run.safety.interventions)
    outcomes, run.outcome_details = run_outcomes(trace, run.robot, run.reaches, run.schedule.control_dt,
                                                 run.sc.outcomes, breaches)
    metrics.update(outcomes)
    metrics.update({
        "sim_time_s": sim_time, "wall_time_s": wall, "setup_time_s": setup,
        "real_time_factor": sim_time / wall if wall > 0 else float("inf"),
        "contact_steps": contact_steps, "safety_events": len(run.safety.events),
        "torque_saturation_steps": run.safety.saturated_steps,
    })
    return metrics, per_joint


def plugin_versions(run: Runner) -> dict[str, Any]:
    """Type, package and version of every plugin the run used."""
    sc, registry = run.sc, run.registry
    out: dict[str, Any] = {}
    for kind, cfg in (("robot", sc.robot), ("backend", sc.backend), ("planner", sc.planner),
                      ("controller", sc.controller), ("patient", getattr(sc.patient, "model", None))):
        if cfg is None:
            continue
        p = registry.get(kind, cfg.type).provider
        out[kind] = {"type": cfg.type, "package": p.package, "version": p.version}
    out["sensors"] = {n: {"type": c.type, **vars(registry.get("sensor", c.type).provider)}
                      for n, c in sc.sensors.items()}
    return out


def run_inputs(run: Runner) -> dict[str, Any]:
    """Fingerprints of what drove the run besides its plugins, so a replay can tell whether they were the same."""
    rng_state = json.dumps(run.rng.bit_generator.state, sort_keys=True, default=str).encode()
    return {"seed": run.sc.seed, "target_timeline": [[f["t"], f["trigger"]] for f in run.fired],
            "sensor_noise": hashlib.sha256(rng_state).hexdigest()[:16],
            **(run.patient.inputs() if run.patient is not None else {})}


def patient_summary(run: Runner) -> dict[str, Any] | None:
    """Who the run was for (pseudonymous), what their profile changed, and the effective limits' sources."""
    p = run.sc.patient
    if p is None and not run.limit_sources.by_joint:
        return None
    out: dict[str, Any] = {"effective_limits": run.limit_sources.as_dict(), "replaced_targets": run.replaced}
    if p is not None:
        out.update(id=p.id, side=p.side, segments=run.segments,
                   simulated=None if run.patient is None else p.model.type)
    return out


def build_summary(run: Runner, metrics: dict[str, float], per_joint: dict[str, Any]) -> dict[str, Any]:
    """The summary document: scenario, plugins, timing, metrics, verdicts, safety, events, plans, reports.

    A safety stop fails the run unless the scenario's expectations are about safety events.
    """
    sc = run.sc
    verdicts = evaluate(sc.expect, metrics)
    unexpected_trip = run.safety.tripped and "safety_events" not in sc.expect
    return {
        "scenario": str(run.loaded.path), "name": sc.name or run.loaded.path.stem,
        "rehabkit_version": rehabkit.__version__, "seed": sc.seed, "plugins": plugin_versions(run),
        "passed": all(v["passed"] for v in verdicts) and not unexpected_trip,
        "sim_time_s": metrics["sim_time_s"], "wall_time_s": metrics["wall_time_s"],
        "real_time_factor": metrics["real_time_factor"],
        "metrics": metrics, "per_joint": per_joint, "expectations": verdicts,
        "safety": {"tripped": run.safety.tripped, "events": [e.as_dict() for e in run.safety.events],
                   "interventions": [e.as_dict() for e in run.safety.interventions],
                   "plan_warnings": run.plan_warnings},
        "patient": patient_summary(run),
        "inputs": run_inputs(run),
        "outcomes": {k: v for k, v in run.outcome_details.items() if k != "interaction_force_n"},
        "events": run.fired, "plans": run.plans, "notes": run.notes, "actions": run.acted,
        "reports": {name: text for name, s in run.sensors.items() if (text := s.report(metrics))},
    }
