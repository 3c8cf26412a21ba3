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
from rehabkit.core.plugins.lifecycle import Contribution, Section
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
def rehabkit_configure_robot(setup) -> None:
    from rehabkit.rehab.admission import adapt_segments

    setup.robot_config, setup.extras["segments"] = adapt_segments(setup.robot_config, setup.sc.patient,
                                                                  setup.loaded.source)


@hookimpl
def rehabkit_narrow_limits(setup):
    from rehabkit.rehab.admission import profile_narrowings

    profile = setup.sc.patient
    return profile_narrowings(setup.robot.model, profile, setup.loaded.source) if profile is not None else []


@hookimpl
def rehabkit_force_limit(setup):
    profile = setup.sc.patient
    return profile.comfort.max_interaction_force_n if profile is not None else None


@hookimpl
def rehabkit_admit_targets(setup) -> None:
    from rehabkit.rehab.admission import admit_targets

    sc = setup.sc
    setup.replaced = admit_targets(setup.targets, sc.task, setup.robot, setup.robot_limits, setup.limit_sources,
                                   sc.patient, setup.loaded.source)


@hookimpl
def rehabkit_run_finished(setup, record):
    from rehabkit.rehab.run_outcomes import outcome_series, run_outcomes

    breaches = sum(e.rule not in ("ramp-in", "ramp-out") for e in record.interventions)
    metrics, details = run_outcomes(record.trace, setup.robot, record.movements, setup.schedule.control_dt,
                                    setup.sc.outcomes, breaches)
    return Contribution(
        metrics=metrics,
        sections={"patient": patient_summary(setup),
                  "outcomes": {k: v for k, v in details.items() if k != "interaction_force_n"}},
        series=outcome_series(record.trace.t, details, setup.schedule.log_every),
    )


def patient_summary(setup) -> dict | None:
    """Who the run was for (pseudonymous), what their profile changed, and the effective limits' sources."""
    p = setup.sc.patient
    if p is None and not setup.limit_sources.by_joint:
        return None
    out = {"effective_limits": setup.limit_sources.as_dict(), "replaced_targets": setup.replaced}
    if p is not None:
        out.update(id=p.id, side=p.side, segments=setup.extras.get("segments", {}),
                   simulated=None if setup.patient is None else p.model.type)
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
