"""Between the planner and the reference: every plan is asked for, checked and accounted for here.

A joint-space plan that breaks a joint limit (the run's narrowed ones) or asks for a
scene action the backend can't do is not executed. A plan whose hand path leaves
the keep-in box is executed (the box is watched, not planned around) but the
summary and the CLI say before it moves where and when the safety layer will stop it.
"""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.capabilities import scene_actions
from rehabkit.core.kinds.interfaces import Plan, PlanRequest, Target
from rehabkit.core.kinds.metric import MetricCatalogue, combine
from rehabkit.core.safety.keep_in import plan_exit
from rehabkit.core.safety.limit_breach import CHECK_DT, LimitBreach
from rehabkit.core.setup.space import JointSpace


class PlanGate:
    """Asks the scenario's planner, checks what it answers, keeps the plans' diagnostics and warnings."""

    RUN_STATE_FIELDS = ("metrics", "warnings")  # (what a run adds: a snapshot's)

    def __init__(self, setup, space: JointSpace, catalogue: MetricCatalogue):
        self.planner, self.robot, self.safety, self.space = setup.planner, setup.robot, setup.safety, space
        self.scene_actions = tuple(scene_actions(setup.backend))
        self.catalogue = catalogue
        self.duration = setup.sc.duration  # (what of a plan can run: up to the run's end)
        self.metrics: dict[str, float] = {}
        self.warnings: list[dict] = []

    def ask(self, t: float, q: np.ndarray, qd: np.ndarray, targets: list[Target], planner=None) -> Plan:
        """The plan from ``(q, qd)`` through ``targets`` by ``planner`` (default: the scenario's; an event's own
        settings make another); its ``PlanningError`` passes through."""
        return (planner or self.planner).plan(PlanRequest(t, q.copy(), qd.copy(), targets, self.robot))

    def problem(self, plan: Plan, t: float = 0.0) -> tuple[str | None, LimitBreach | None, tuple[str, ...]]:
        """Why the plan made at ``t`` must not run, with the limit breach (up to the run's end) or the scene actions
        the backend can't do when that is why; ``(None, None, ())`` when it may run."""
        breach = self.space.limit_breach(plan, self.duration - t + CHECK_DT)
        if breach is not None:
            return f"planned trajectory: {breach.describe()}", breach, ()
        bad = tuple(sorted({kind for _, kind, _ in plan.actions if kind not in self.scene_actions}))
        if bad:
            can = ", ".join(self.scene_actions) or "none"
            return f"plan action(s) {list(bad)} unknown; the backend can do: {can}", None, bad
        return None, None, ()

    def warn_box(self, t: float, plan: Plan) -> str | None:
        """The keep-in box is watched, not planned around: say before moving where a plan will leave it (the
        warning, kept; None if it stays inside)."""
        if self.safety.keep_in is None:
            return None
        warning = plan_exit(t, plan.trajectory, self.space.hand_world, self.safety.keep_in)
        if warning is None:
            return None
        self.warnings.append(warning)
        return warning["message"]

    def account(self, plan: Plan) -> Plan:
        """Merge the plan's diagnostics into the run's, each by its metric's rule (default: the worst)."""
        for key, value in plan.diagnostics.items():
            self.metrics[key] = combine(self.catalogue.get(key).combine, self.metrics.get(key), value)
        return plan
