"""The ROS layer in every run (an extension): its ``ros:`` section, and the bag it writes when asked
(``ros: {bag: true}``, or ``rehabkit run --bag``)."""

from __future__ import annotations

import time

from pydantic import Field

from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Contribution, Section
from rehabkit.models.strict import StrictModel


class RosSpec(StrictModel):
    """What the run gives ROS tools."""

    bag: bool = Field(False, description="write run.mcap beside run.rrd: a ROS 2 bag of the run (joint states, "
                      "reference, tf, robot description, safety events and notes)")


@hookimpl
def rehabkit_scenario_sections(registry) -> dict[str, Section]:
    return {"ros": Section(RosSpec, None, "what the run gives ROS tools (a ROS 2 bag)")}


@hookimpl
def rehabkit_run_finished(setup, record) -> Contribution | None:
    spec = getattr(setup.sc, "ros", None)
    if spec is None or not spec.bag or setup.out_dir is None:
        return None
    from rehabkit.ros.bag import write_bag
    from rehabkit.ros.description import robot_description

    description = robot_description(setup.robot, setup.sc.robot, setup.context.resolve)
    start_ns = time.time_ns() - round(float(record.trace.t[-1] if len(record.trace.t) else 0.0) * 1e9)
    topics = write_bag(setup.out_dir / "run.mcap", setup, record, start_ns, description)
    return Contribution(sections={"bag": {"file": "run.mcap", "topics": topics}})
