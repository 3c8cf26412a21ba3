"""The rehab layer as a run-lifecycle extension (entry point ``rehabkit.extensions: rehab``).

With a patient profile it adapts the robot to the person's segments, narrows the
limits to their range and comfort, refuses (or replaces) targets outside that
range and adds their comfortable interaction force to the envelope. For every run
it adds the outcome measures (reaches, SPARC, path-length ratio, time to target,
range of motion, assistance ratio, peak interaction force, interventions) and the
``patient`` and ``outcomes`` sections of ``summary.json``.
"""

from __future__ import annotations

from pydantic import Field

from rehabkit.core.kinds.metric import Metric
from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Admission, Contribution, ExtensionState, RobotSettings, RunInfo, Section
from rehabkit.models.strict import StrictModel

METRICS = (
    Metric("reaches", "count", outcome=True, description="planned movements counted as reaches"),
    Metric("reaches_planned", "count", description="movements the task's plans hold, begun within the run or not"),
    Metric("reaches_completed", "count", outcome=True, description="reaches that got to their target and stayed"),
    Metric("sparc", outcome=True, description="smoothness: spectral arc length of the hand's speed (mean)"),
    Metric("path_length_ratio", outcome=True, description="hand path length / straight line (mean)"),
    Metric("time_to_target_s", "s", outcome=True, description="time until the hand stays at the target (mean)"),
    Metric("assistance_ratio", outcome=True, description="the robot's share of the positive work done"),
    Metric("peak_interaction_force_n", "N", outcome=True,
           description="largest force between person and robot: at the hand (from the person's joint torques), or "
                       "an embodied person's largest cuff force (measured)"),
    Metric("safety_interventions", "count", outcome=True, description="trips and clipping episodes"),
    Metric("rom_deg_*", "deg", outcome=True, description="range of motion of a revolute joint"),
    Metric("rom_m_*", "m", outcome=True, description="range of motion of a prismatic joint"),
)


@hookimpl
def rehabkit_metrics():
    return list(METRICS)


@hookimpl
def rehabkit_configure_robot(scenario, source, robot_config) -> RobotSettings:
    from rehabkit.rehab.admission import adapt_segments

    config, segments = adapt_segments(robot_config, scenario.patient, source)
    return RobotSettings(config, {"segments": segments})  # (segments: what became of each length, for the summary)


@hookimpl
def rehabkit_narrow_limits(scenario, source, model):
    from rehabkit.rehab.admission import profile_narrowings

    profile = scenario.patient
    return profile_narrowings(model, profile, source) if profile is not None else []


@hookimpl
def rehabkit_force_limit(scenario):
    profile = scenario.patient
    return profile.comfort.max_interaction_force_n if profile is not None else None


@hookimpl
def rehabkit_admit_targets(scenario, source, targets, robot, robot_limits, limit_sources) -> Admission:
    from rehabkit.rehab.admission import admit_targets

    admitted = dict(targets)  # (admit_targets puts a replacement in place)
    replaced = admit_targets(admitted, scenario.task, robot, robot_limits, limit_sources, scenario.patient, source)
    return Admission({name: t for name, t in admitted.items() if t is not targets[name]}, tuple(replaced))


@hookimpl
def rehabkit_run_finished(run: RunInfo, record, state: ExtensionState) -> Contribution:
    from rehabkit.rehab.run_outcomes import outcome_series, run_outcomes

    breaches = sum(e.rule not in ("ramp-in", "ramp-out") for e in record.interventions)
    metrics, details = run_outcomes(record.trace, run.robot, record.movements, run.schedule.control_dt,
                                    run.scenario.outcomes, breaches)
    return Contribution(
        metrics=metrics,
        sections={"patient": patient_summary(run, state.notes.get("segments", {})),
                  "outcomes": {k: v for k, v in details.items() if k != "interaction_force_n"}},
        series=outcome_series(record.trace.t, details, run.schedule.log_every),
    )


def patient_summary(run: RunInfo, segments: dict) -> dict | None:
    """Who the run was for (pseudonymous), what their profile changed (``segments``: what became of each segment
    length), and the effective limits' sources."""
    p = run.scenario.patient
    if p is None and not run.limit_sources.by_joint:
        return None
    out = {"effective_limits": run.limit_sources.as_dict(), "replaced_targets": list(run.replaced)}
    if p is not None:
        out.update(id=p.id, side=p.side, segments=segments, simulated=None if run.patient is None else p.model.type)
    return out


class OutcomeSpec(StrictModel):
    """How movements are cut into reaches for the outcome measures."""

    tolerance_m: float = Field(0.01, gt=0, description="target radius: a reach ends when the hand is this close")
    dwell_s: float = Field(0.2, ge=0, description="... and stays for this long")
    min_reach_m: float = Field(0.02, ge=0, description="movements shorter than this are not counted as reaches")


@hookimpl
def rehabkit_scenario_sections(registry) -> dict[str, Section]:
    from rehabkit.rehab.profile import profile_model

    return {"outcomes": Section(OutcomeSpec, OutcomeSpec(), "how movements are cut into reaches for the outcome "
                                                          "measures"),
            "patient": Section(profile_model(registry), None, "the patient's profile, inline or a file path",
                               file=True, plugins={"model": "patient"})}
