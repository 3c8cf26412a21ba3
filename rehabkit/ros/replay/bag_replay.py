"""A real session's bag, replayed: the person's side of a session recorded on a robot, against another controller or
planner, with the outcome measures of both side by side.

The session's measures come from the bag itself (its joint states resampled at the control rate, the person's
recorded wrench as joint torques at the recorded postures, a reach from each target shown to the next), computed by
the same functions as the replay's (:func:`rehabkit.rehab.run_outcomes.run_outcomes`), on the same robot model.
"""

from __future__ import annotations

import math
import re
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from rehabkit.core.io import atomic_write_json
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.plugins.registry import PluginRegistry, default_registry
from rehabkit.core.results.record import Movement
from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.rehab.replay import Replay, overrides_label
from rehabkit.rehab.run_outcomes import run_outcomes
from rehabkit.ros.description import links
from rehabkit.ros.replay.bag_content import BagError, Where
from rehabkit.ros.replay.bag_scenario import (
    extra_joints,
    joint_order,
    plans_said,
    shown_targets,
    write_session_scenario,
)
from rehabkit.ros.replay.deviation import largest_deviation
from rehabkit.ros.replay.session_bag import SessionBag, read_session, reading_once

SESSION_SCENARIO = "replayed_session.yaml"  # the scenario the session was replayed in, beside the replay's outputs
SESSION_MEASURES = "session.json"  # the recorded session's own outcome measures, the table's first column


def base_frames(robot) -> dict[str, np.ndarray]:
    """The frames a target may be given in besides the world's, each with its pose in the robot's base frame (the
    one its kinematics are in, 4x4): its model's bodies fixed to the base — a URDF's ``world`` link, a ``base``
    turned from ``base_link`` — and ``base_link`` (ROS's name for the base) where the model has none of that name."""
    model = robot.model.pin_model
    fixed = {link.name: model.frames[link.frame].placement.homogeneous for link in links(model)
             if model.frames[link.frame].parentJoint == 0}
    return {**fixed, "base_link": fixed.get("base_link", np.eye(4))}


def session_trace(bag: SessionBag, robot, patient, dt: float) -> Trace:
    """The session as a run's trace at the control step ``dt``: joints, the torque sent (the joint states' effort,
    NaN where the bag has none) and the person's torques (from the recorded wrench, where the run has a person)."""
    order = joint_order(bag, list(robot.model.joint_names))
    t = np.arange(int(math.floor(bag.joints.t[-1] / dt + 1e-9)) + 1) * dt
    q = bag.joints.at(t)[:, order]
    qd = bag.velocity.at(t)[:, order] if bag.velocity is not None else np.gradient(q, dt, axis=0)
    tau = bag.effort.at(t)[:, order] if bag.effort is not None else np.full_like(q, np.nan)
    tau_h = None
    if patient is not None and bag.wrench is not None:  # the recorded person: their torque at the recorded postures
        goal = np.zeros(3)
        tau_h = np.array([patient.torque(float(t[k]), q[k], qd[k], goal) for k in range(len(t))])
    nan = np.full_like(q, np.nan)
    return Trace(t, q, qd, tau, nan, nan, tau_h=tau_h)


def session_reaches(bag: SessionBag, runner: Runner, n: int, dt: float) -> list[Movement]:
    """A movement from each target shown to the next (the last to the end), to the target as the replay had it."""
    a = runner.setup
    shown = shown_targets(bag)
    out = []
    for i, target in enumerate(shown):
        k0 = min(n - 1, int(round(target.t / dt)))
        k1 = min(n, int(round(shown[i + 1].t / dt))) if i + 1 < len(shown) else n
        goal = np.asarray(a.targets[f"shown_{i + 1}"].pose[:3, 3], float)  # (a posture's too: its hand pose)
        out.append(Movement(k0, k1, goal, goal))
    return out


def wrench_frame_refusal(bag: SessionBag, robot) -> BagError | None:
    """The bag's wrench given in a frame the robot has not (said at its first message), or None."""
    w = bag.wrench
    model = robot.model.pin_model
    if w is None or (w.frame and model.existFrame(w.frame)):
        return None
    frames = ", ".join(f.name for f in model.frames if f.name != "universe")
    return BagError(bag.path, "wrench", f"frame_id '{w.frame}' is not a frame of robot '{robot.model.name}' (its "
                                        f"frames: {frames}): record the wrench in a frame of the robot, or name the "
                                        "frame it is given in and acts at: --set patient.model.frame=FRAME",
                    where=Where(w.topic, float(w.t[0]), bag.t0_ns + round(float(w.t[0]) * 1e9)),
                    field="header.frame_id")


def replay_bag(bag_path: str | Path, scenario: str | Path, topics: dict[str, str] | None = None,
               overrides: Iterable[str] = (), out_dir: str | Path | None = None,
               registry: PluginRegistry | None = None, progress: bool = False,
               say: Callable[[str], None] | None = None) -> Replay:
    """Replay the session recorded in ``bag_path`` on ``scenario`` with ``overrides`` (e.g. another controller), its
    ``topics`` by role where named (:func:`rehabkit.ros.replay.session_bag.parse_topics`; the others at their defaults);
    outputs in ``out_dir`` (default ``<bag>-replay-<values>`` beside the bag): the run's, with the scenario the
    session was replayed in (:data:`SESSION_SCENARIO`) and the session's own measures (:data:`SESSION_MEASURES`).
    What the replay does without (a gap bridged, joints the robot lacks, a field left out, a person's wrench or a
    reference the bag has none of) is given to ``say`` before anything is simulated, and kept in the session's
    ``said``.

    Raises:
        ScenarioError: the bag can't be replayed as asked (a topic missing, joints the robot lacks, a value that is
            not finite, a wrench frame the robot has not: a :class:`BagError` at the message), or the scenario or
            overrides are invalid. Nothing is left of the output folder where it did not exist.
    """
    bag_path, scenario, overrides = Path(bag_path), Path(scenario), list(overrides)
    registry = registry or default_registry()
    with reading_once():  # (the recorded-wrench patient reads the bag this reads: its messages deserialised once)
        return _replay_bag(bag_path, scenario, topics, overrides, out_dir, registry, progress, say)


def _replay_bag(bag_path: Path, scenario: Path, topics: dict[str, str] | None, overrides: list[str],
                out_dir: str | Path | None, registry: PluginRegistry, progress: bool,
                say: Callable[[str], None] | None) -> Replay:
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.setup.assembly import assemble

    bag = read_session(bag_path, topics)
    topics = bag.topics  # (those read: a wrench not named and not in the bag is none)
    plain = load_scenario(scenario, [], registry)
    robot = assemble(plain, registry, default_extensions(), upto="targets").robot
    joint_order(bag, list(robot.model.joint_names))  # (the robot's joints, each in the bag: else refused first)
    framed = any(o.split("=", 1)[0].strip() == "patient.model.frame" for o in overrides)
    if topics["wrench"] and not framed and (refused := wrench_frame_refusal(bag, robot)) is not None:
        raise refused
    timed = plain.model.planner.model_dump().get("segment_durations") is not None
    said = [str(r) for r in [*bag.remarks, *extra_joints(bag, robot), *(plans_said(bag, timed) if topics["targets"]
                                                                        else [])]]
    said += [f"{bag_path}: {gap}: bridged by interpolation" for gap in bag.gaps]
    for line in said:
        if say is not None:
            say(line)
    stem = re.sub(r"[^A-Za-z0-9._-]+", "-", bag_path.name.removesuffix(".mcap"))
    label = overrides_label(overrides)
    out = Path(out_dir) if out_dir is not None else bag_path.resolve().parent / f"{stem}-replay-{label}"
    fresh = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        path = write_session_scenario(out / SESSION_SCENARIO, scenario, bag, robot, base_frames(robot), topics,
                                      plain.model.patient is not None, timed)
        loaded = load_scenario(path, overrides, registry)
        runner = Runner(loaded, registry, out, progress=progress)
        result = runner.run()
        session = session_summary(bag, runner, result.summary, result.trace)
        session["said"] = said
        atomic_write_json(out / SESSION_MEASURES, {k: v for k, v in session.items() if k != "metric_info"})
    except Exception:  # (refused, or failed: no half-written folder left; a folder that was there keeps the rest)
        if fresh:
            shutil.rmtree(out, ignore_errors=True)
        else:
            (out / SESSION_SCENARIO).unlink(missing_ok=True)
        raise
    # (no inputs to compare: the replay's person is the bag's by construction)
    return Replay(session, result, {}, overrides)


def session_summary(bag: SessionBag, runner: Runner, replayed: dict, replay: Trace | None = None) -> dict:
    """The recorded session's outcome measures, as a summary's ``metrics`` (beside what ``Replay`` compares), and
    the replay's largest deviation from its joints (``deviation``: of the ``replay``'s trace, where given)."""
    a = runner.setup
    dt = a.schedule.control_dt
    trace = session_trace(bag, runner.robot, a.patient, dt)
    metrics, details = run_outcomes(trace, runner.robot, session_reaches(bag, runner, len(trace.t), dt), dt,
                                    a.sc.outcomes, 0)
    metrics["safety_interventions"] = float("nan")  # (what the robot's safety layer did is not in the bag)
    if bag.wrench is None:  # (no person's wrench read: their share and force unknown, not none)
        metrics["assistance_ratio"] = metrics["peak_interaction_force_n"] = float("nan")
    return {"label": f"recorded ({bag.path.name})", "bag": str(bag.path), "duration_s": bag.duration_s,
            "metrics": metrics, "metric_info": replayed.get("metric_info", {}),
            "outcomes": {k: v for k, v in details.items() if k != "interaction_force_n"},
            "gaps": [str(g) for g in bag.gaps],
            "deviation": None if replay is None else largest_deviation(trace, replay, runner.robot.model)}
