"""What a run leaves behind for its metrics and summary: the trace and what happened, not the live runner."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rehabkit.core.kinds.trace import Trace


@dataclass
class Movement:
    """One planned movement (a reach, for the outcome measures): control-step indices ``[k0, k1)``, the hand's
    goal (robot base frame), the goal in the planner's space (joint values, or the same position) and the task target
    it goes to (``name``; None where the plan's targets were not named, e.g. a controller's own plan)."""

    k0: int
    k1: int
    goal: np.ndarray
    target: np.ndarray
    name: str | None = None


@dataclass
class RunRecord:
    """A finished run's record.

    Attributes:
        trace: Control-rate arrays, trimmed to the steps run.
        wall_s: Wall time of the loop; ``setup_s`` from loading to the first step.
        contact_steps: Steps with a robot collision (floor, objects).
        goal: Where the last plan ends (joint values or a hand position).
        movements: Every plan's movements, cut where a replan took over.
        plans: One entry per plan for the summary; ``plan_metrics`` their diagnostics combined.
        fired: Task events as they fired; ``acted`` scene actions done; ``notes`` plugins' messages.
        plan_warnings: What plans were found to run into (the keep-in box) before they ran.
        no_plan: Why the first plan failed, if it did: the robot never moved, so no expectation counts as met.
        interventions: Every time a command was changed, by this host's safety layer or the robot side (a bridge
            holding a stale command), in time order.
    """

    trace: Trace
    wall_s: float
    setup_s: float
    contact_steps: int
    goal: np.ndarray
    movements: list[Movement]
    plans: list[dict[str, Any]]
    plan_metrics: dict[str, float]
    fired: list[dict[str, Any]]
    acted: list[dict[str, Any]]
    notes: list[dict[str, Any]]
    plan_warnings: list[dict[str, Any]]
    extra_metrics: dict[str, float] = field(default_factory=dict)  # the loop's own (sensor-thread overruns)
    no_plan: str | None = None  # why the first plan was refused or failed: the robot never moved
    interventions: list[Any] = field(default_factory=list)  # the safety layer's and the robot side's, in time order
    first_contact: dict[str, Any] | None = None  # when, what and where the robot first touched something
    safety: Any = None  # the run's safety layer as the run left it: tripped or not, its events (a SafetyLayer)
    extension_states: dict[str, Any] = field(default_factory=dict)  # each extension's state in this run (its tap)

