"""Where a run starts and its first plan: made by ``rehabkit validate`` without running it, so that a task the
planner refuses is bad input, located in the scenario file, before anything moves."""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.interfaces import PlanningError, PlanRequest
from rehabkit.core.safety.keep_in import plan_exit
from rehabkit.core.safety.limit_breach import CHECK_DT
from rehabkit.core.setup.assembly import Assembly
from rehabkit.core.setup.checks import at_target
from rehabkit.core.setup.dynamics_check import missing_inertia, plan_torque
from rehabkit.core.setup.errors import PluginSetupError, SetupError
from rehabkit.core.setup.targets import looks_like_radians


def start_posture(a: Assembly) -> np.ndarray:
    """The task's start: a joint target's values, or a Cartesian one's first IK solution within the ranges."""
    task = a.sc.task
    name = task.start or task.order()[0]
    target = a.targets[name]
    if target.q is not None:
        return target.q.copy()
    try:
        solutions = a.robot.solve_ik(target.pose, free=target.free) if target.pose is not None else []
    except NotImplementedError:
        solutions = []
    lim = a.robot.model.limits
    inside = [s for s in solutions if np.all(s >= lim.lower) and np.all(s <= lim.upper)]
    if not inside:
        raise SetupError(f"task.start: target '{name}' is Cartesian and the robot's IK gives no configuration "
                         "for it within the joint ranges", fix="start from a joint-space target")
    return inside[0]


def check_first_plan(a: Assembly) -> list[str]:
    """Make the task's first plan without running it (``rehabkit validate``); a planner's refusal is located at
    the setting it names. Skipped where the run alone can plan: sensed targets, a controller planning itself.
    Returns what the run would warn of before it moves: the plan leaving the keep-in box, where and when."""
    sc = a.sc
    names = sc.task.order()
    sensed = any(t.sensor for t in sc.task.targets if t.name in names)
    if not names or sensed or a.controller.reference == "own":
        return []
    q0 = start_posture(a)
    try:
        plan = a.planner.plan(PlanRequest(0.0, q0, np.zeros_like(q0), [a.targets[n] for n in names], a.robot))
    except PlanningError as exc:
        raise first_plan_refusal(a, exc) from exc
    if (breach := a.space.limit_breach(plan, a.sc.duration + CHECK_DT)) is not None:  # as the run's plan gate does
        raise breach_refusal(a, breach)
    warnings = [w for w in (outlasting(a, plan.trajectory.duration), all_small(a)) if w] + missing_inertia(a.robot, q0)
    if a.planner.space == "joint":  # (what the joints need to follow it: a Cartesian plan's joints are the run's)
        warnings += plan_torque(a.robot, plan.trajectory, a.sc.duration)
    if a.safety.keep_in is None:
        return warnings
    warning = plan_exit(0.0, plan.trajectory, a.space.hand_world, a.safety.keep_in)
    return warnings + ([warning["message"]] if warning is not None else [])


def all_small(a: Assembly) -> str | None:
    """Every posture of the task given in degrees within ±2π on its revolute joints: radians, most likely — refused
    nowhere where they fit the ranges (the arm barely moves), so said at the first of them."""
    revolute = np.asarray(a.robot.model.revolute, bool)
    given = [(i, t, "joints_deg" if t.joints_deg is not None else "joints") for i, t in enumerate(a.sc.task.targets)
             if t.joints_deg is not None or t.joints is not None]
    if len(given) < 2:  # (one small posture is a posture)
        return None
    values = [np.abs(np.asarray(getattr(t, key), float)) for _, t, key in given]
    if any(len(v) != len(revolute) for v in values) or \
            not looks_like_radians(np.concatenate(values), np.tile(revolute, len(values))):
        return None
    turning = np.concatenate([v[revolute] for v in values])
    i, _, key = given[int(np.argmax([v[revolute].max() for v in values]))]  # (at the posture that moves most)
    at = a.loaded.source.key_marks.get(("task", "targets", i, key))
    return (f"task.targets.{i}.{key}{f' ({at})' if at else ''}: every posture's revolute values are within ±2π "
            f"(the largest {turning.max():.3g}): written in radians? {key} takes degrees for a revolute joint; "
            "joints_rad takes SI (radians, and metres)")


def outlasting(a: Assembly, plan_s: float) -> str | None:
    """The task's first plan lasting longer than the run: said at the planner's timing setting (where the file
    writes one: segment_durations in milliseconds by mistake) and the run's duration, with the numbers."""
    run_s = a.sc.duration
    if plan_s <= run_s + 1e-9:
        return None
    source, planner = a.loaded.source, a.sc.planner
    timing = next((k for k in ("segment_durations", "duration", "durations", "speed", "max_speed_deg_s")
                   if ("planner", k) in source.key_marks), None)
    at = source.key_marks.get(("planner", timing) if timing else ("planner", "type"))
    where = f"planner.{timing}" if timing else "planner"
    ends = source.key_marks.get(("duration",))
    return (f"{where}{f' ({at})' if at else ''}: the plan lasts {plan_s:.4g} s and the run {run_s:g} s "
            f"(duration{f' at {ends}' if ends else ''}): the task cannot finish — {run_s / plan_s:.1%} of it is run "
            f"(`rehabkit plugins --fields {planner.type}` gives the timing's units; lengthen duration or shorten the "
            "plan)")


def _fix(a: Assembly, breach) -> str:
    """What puts a plan within a limit it breaks: where the limit was set, and for a speed, the planner's timing (a
    refusal's ``fix``)."""
    source = a.limit_sources.by_joint.get(breach.joint, {}).get(
        breach.quantity if breach.quantity == "velocity" else ("lower" if breach.value < breach.limit else "upper"))
    where = {"safety": f"the safety envelope's (safety.joints.{breach.joint})",
             "patient": "the patient profile's"}.get(source[0], f"{source[0]}'s") if source else "the robot's own"
    if breach.quantity == "velocity":
        return (f"the limit is {where}: give the plan more time (the planner's timing settings, `rehabkit plugins "
                f"--fields {a.sc.planner.type}`) or the joint a higher speed limit there")
    return f"the limit is {where}: plan through postures inside it (other targets or via points) or widen it there"


def breach_refusal(a: Assembly, breach) -> PluginSetupError:
    """The first plan breaking a limit in force, located and with its fix: the same words from ``validate`` and
    from a run (which said it unlocated, blaming a patient's profile where there was none)."""
    small = all_small(a)  # (radians under joints_deg break a range of 0° by a hair: the units are the cause)
    refusal = first_plan_refusal(a, PlanningError(f"planned trajectory: {breach.describe()}",
                                                  fix=_fix(a, breach) + (f"; but {small}" if small else "")))
    refusal.breach = breach  # (what it says, as fields)
    return refusal


def first_plan_refusal(a: Assembly, why: Exception | str) -> PluginSetupError:
    """The task's first plan failed or broke a limit: bad input, located at the target it names, else at the
    planner's setting it names, else at the planner."""
    exc = why if isinstance(why, Exception) else PlanningError(why)
    return at_target(a, exc) or PluginSetupError.refused(a.loaded.source, ("planner",), "planner", a.sc.planner,
                                                          exc)


