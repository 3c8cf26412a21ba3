"""The ROS layer in every run (an extension): its ``ros:`` section, and the bag it writes when asked
(``ros: {bag: true}``, or ``rehabkit run --bag``)."""

from __future__ import annotations

import time

from pydantic import Field

from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Contribution, ExtensionState, RunInfo, Section
from rehabkit.models.strict import StrictModel


class RosSpec(StrictModel):
    """What the run gives ROS tools."""

    bag: bool = Field(False, description="write run.mcap beside run.rrd: a ROS 2 bag of the run (joint states, "
                      "reference, tf, robot description, a person's wrench, targets, sensor readings, safety events "
                      "and notes)")
    epoch_ns: int | None = Field(None, ge=0, description="the Unix time [ns] the bag stamps the run's start with "
                                 "(default: when the run starts; a replay of a session's bag: the session's start, "
                                 "its first joint state's stamp)")


@hookimpl
def rehabkit_scenario_sections(registry) -> dict[str, Section]:
    return {"ros": Section(RosSpec, None, "what the run gives ROS tools (a ROS 2 bag)")}


def _wanted(run: RunInfo) -> bool:
    spec = getattr(run.scenario, "ros", None)
    return spec is not None and spec.bag and run.out_dir is not None


@hookimpl
def rehabkit_narrow_limits(scenario, source, model) -> list:
    """No limits of its own: the robot built, a bag is refused (``validate`` says so, at the setting) for a robot
    without a tree model — a parallel mechanism's closed loops, which neither a URDF nor /tf can hold — instead of
    failing when the run opens it."""
    spec = getattr(scenario, "ros", None)
    if spec is None or not spec.bag:
        return []
    try:
        _ = model.pin_model  # (built here, or why not)
    except Exception as exc:  # noqa: BLE001 (what Pinocchio says of it is the reason)
        from rehabkit.core.scenario.errors import Diagnostic, ScenarioError

        mark = source.key_marks.get(("ros", "bag")) or source.value_marks.get(("ros", "bag")) or source.value_marks[()]
        raise ScenarioError([Diagnostic(mark, "ros.bag", f"robot '{model.name}' has no tree model for a "
                                        f"bag's /robot_description and /tf (a closed kinematic loop: {exc})",
                                        "run it without --bag / ros.bag")]) from None
    return []


@hookimpl
def rehabkit_run_opened(run: RunInfo):
    """The run's bag, as it goes (the recorder: given back as ``state.tap`` at the run's end)."""
    if not _wanted(run):
        return None
    from rehabkit.ros.bag import BagRecorder
    from rehabkit.ros.description import robot_description

    description = robot_description(run.robot, run.scenario.robot, run.resolve)
    start = run.scenario.ros.epoch_ns if run.scenario.ros.epoch_ns is not None else time.time_ns()
    return BagRecorder(run.out_dir / "run.mcap", run, start, description)


@hookimpl
def rehabkit_run_finished(run: RunInfo, record, state: ExtensionState) -> Contribution | None:
    recorder = state.tap  # (the BagRecorder its run_opened returned)
    if recorder is None:
        return None
    return Contribution(sections={"bag": {"file": "run.mcap", "topics": recorder.finish(run, record)}})
