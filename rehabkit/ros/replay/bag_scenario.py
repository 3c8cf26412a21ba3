"""The scenario a recorded session is replayed in: the user's scenario, with the session's start posture, duration,
targets as they were shown (each plan at its time, a replan through its targets:
:mod:`rehabkit.ros.replay.bag_plans`) and
its person (their recorded wrench) put in.

It is written as a file that ``extends:`` the user's (``replayed_session.yaml`` in the replay's folder), so what ran
can be read, validated and run again, and an error in it is located like any other.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import yaml

from rehabkit.ros.replay.bag_content import BagError, Remark, Where
from rehabkit.ros.replay.bag_plans import session_plans
from rehabkit.ros.replay.session_bag import TOPICS, SessionBag, ShownTarget

WORLD_FRAMES = ("world", "map")


def joint_order(bag: SessionBag, robot_joints: list[str], role: str = "joint_states",
                names: list[str] | None = None, where: Where | None = None) -> np.ndarray:
    """Indices into the bag's joint names (a message's ``names``, at ``where``: the joint states' by default) of
    the robot's joints, in the robot's order."""
    names = bag.joints.names if names is None else names
    missing = [j for j in robot_joints if j not in names]
    if missing:
        what = "the bag's joint states" if role == "joint_states" else "this posture target"
        raise BagError(bag.path, role, f"no joint(s) {missing} in {what} ({names}); the robot's joints are "
                                       f"{robot_joints}: replay on the robot the session was recorded on",
                       where=where, field="name")
    return np.array([names.index(j) for j in robot_joints])


def extra_joints(bag: SessionBag, robot) -> list[Remark]:
    """What the bag gives of joints the robot lacks (its joint states', its posture targets'): said, not replayed."""
    joints = list(robot.model.joint_names)
    out = []
    for where, names in [(bag.joints.topic, bag.joints.names)] + [(t.where, t.names) for t in bag.targets
                                                                  if t.kind == "joints"]:
        if extra := [n for n in names if n not in joints]:
            out.append(Remark(str(bag.path), where, f"joint(s) {extra} not in robot '{robot.model.name}' (its "
                                                    f"joints: {', '.join(joints)}): not replayed"))
    return out


def _in_base(bag: SessionBag, shown: ShownTarget, base_pose: np.ndarray, base_frames: dict[str, np.ndarray]
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """A shown point's position in the robot's base frame, and a pose's rotation there (None for a point); a target
    in a frame fixed to the base (``base_frames``: each one's pose in the base frame) taken through its pose."""
    import pinocchio as pin

    rot = None if shown.kind == "point" else pin.Quaternion(*shown.values[[6, 3, 4, 5]]).matrix()
    p = shown.values[:3]
    if shown.frame in WORLD_FRAMES:
        inv = np.linalg.inv(base_pose)
        p, rot = inv[:3, :3] @ p + inv[:3, 3], None if rot is None else inv[:3, :3] @ rot
    elif shown.frame in base_frames:
        fixed = base_frames[shown.frame]
        p, rot = fixed[:3, :3] @ p + fixed[:3, 3], None if rot is None else fixed[:3, :3] @ rot
    elif shown.frame:
        raise BagError(bag.path, "targets", f"is in frame '{shown.frame}': give targets in the robot's base frame "
                                            f"({' or '.join(base_frames)}) or the world ({' or '.join(WORLD_FRAMES)})",
                       where=shown.where, field="header.frame_id")
    return p, rot


def shown_targets(bag: SessionBag) -> list[ShownTarget]:
    """The targets shown during the session (``shown_1``, ``shown_2``, … in the replay's task, in this order)."""
    return [t for t in bag.targets if 0.0 <= t.t < bag.duration_s]


def session_task(bag: SessionBag, robot, base_frames: dict[str, np.ndarray], timed: bool = False) -> dict:
    """The ``task:`` section: start where the session started, then each plan as it was (:func:`session_plans`: the
    targets shown while the robot moved on to them in one plan, a new one where it stood), a replan through its
    targets when its first was shown (``timed``: the planner is timed by ``segment_durations`` and plans from its
    first target, as multi-cubic does: each replan from the target before, with its segments' durations)."""
    import pinocchio as pin

    model = robot.model
    order = joint_order(bag, list(model.joint_names))
    start = bag.joints.values[0, order]
    targets: list[dict] = [{"name": "start", "joints_rad": [float(v) for v in start]}]
    shown_all = shown_targets(bag)
    for i, shown in enumerate(shown_all):
        name = f"shown_{i + 1}"
        if shown.kind == "joints":
            idx = joint_order(bag, list(model.joint_names), "targets", shown.names, shown.where)
            targets.append({"name": name, "joints_rad": [float(v) for v in shown.values[idx]]})
        else:
            p, rot = _in_base(bag, shown, np.asarray(model.base_pose, float), base_frames)
            spec = {"name": name, "position": [float(v) for v in p]}
            if rot is not None:
                spec["rpy_deg"] = [float(v) for v in np.degrees(pin.rpy.matrixToRpy(rot))]
            targets.append(spec)
    events = []
    for plan in session_plans(bag, shown_all):
        names = [f"shown_{i + 1}" for i in range(plan.first, plan.last + 1)]
        # (a timed planner plans through its via points: from the target before, where the robot should be)
        event = {"at": round(float(plan.t), 9), "action": "replan",
                 "sequence": [f"shown_{plan.first}" if plan.first else "start", *names] if timed else names}
        if timed:
            event["planner"] = {"segment_durations": [round(d, 9) for d in plan.durations]}
        events.append(event)
    task = {"targets": targets, "start": "start", "sequence": ["start"], "events": events}
    if timed:  # (a timed planner's first plan has a segment: to the first target shown at once, or held till one is)
        if events and events[0]["at"] < 1e-6:
            first = events.pop(0)
            task["sequence"], durations = first["sequence"], first["planner"]["segment_durations"]
        else:
            targets.append({"name": "start_held", "same_as": "start"})
            task["sequence"] = ["start", "start_held"]
            durations = [round(shown_all[0].t if shown_all else bag.duration_s, 9)]
        task["segment_durations"] = durations  # (taken out by the caller: the planner's setting)
    return task


def plans_said(bag: SessionBag, timed: bool) -> list[Remark]:
    """What the replay's plans do without, where it matters: a bag without the joints' reference has its plans told
    apart by the measured joints' speed — an estimate, said where a plan is through several targets or the planner is
    timed (each plan's last movement then given until the next plan began, or the session's end)."""
    shown = shown_targets(bag)
    if bag.reference is not None or not shown:
        return []
    plans = session_plans(bag, shown)
    if not timed and all(p.first == p.last for p in plans):
        return []
    through = [f"shown_{p.first + 1}..shown_{p.last + 1}" for p in plans if p.last > p.first]
    said = f"one plan through {', '.join(through)}" if through else "a plan to each target"
    ends = ("; each plan's last movement given until the next plan began, or the session's end (one that ended "
            "sooner is replayed slower)") if timed else ""
    return [Remark(str(bag.path), "--topics reference", f"no joints' reference (rehabkit's bags: "
                                                        f"{TOPICS['reference']}): plans told apart by the measured "
                                                        f"joints' speed (a target shown while they moved: a via "
                                                        f"point of the plan under way): {said}{ends}")]


def write_session_scenario(path: Path, scenario: Path, bag: SessionBag, robot, base_frames: dict[str, np.ndarray],
                           topics: dict[str, str], has_patient: bool, timed: bool = False) -> Path:
    """``path``: a scenario extending ``scenario`` with the session's task, duration and recorded person."""
    patient: dict = {"model": {"type": "recorded-wrench", "bag": str(bag.path.resolve()), "topic": topics["wrench"],
                               "joint_states": topics["joint_states"]}}
    if not has_patient:  # a profile to hold the recorded person: the session's name as its pseudonymous id
        patient.update(id=re.sub(r"[^A-Za-z0-9_.-]+", "-", bag.path.stem).strip("-.") or "session", side="right")
    if not topics["wrench"]:  # (none: the scenario's own patient, if any)
        patient = None
    doc = {"extends": str(scenario.resolve()),
           "name": f"replay-of-{bag.path.stem}",
           "duration": round(bag.duration_s, 9),
           "ros": {"epoch_ns": int(bag.t0_ns)}}  # (a bag of the replay: stamped on the session's time base)
    if topics["targets"]:  # (none: the scenario's own task, from its own start)
        doc["task"] = session_task(bag, robot, base_frames, timed)
        if timed:
            doc["planner"] = {"segment_durations": doc["task"].pop("segment_durations")}
    if patient is not None:
        doc["patient"] = patient
    took = [w for w, role in (("targets as shown", "targets"), ("the person's recorded wrench", "wrench"))
            if topics[role]]
    head = (f"# written by `rehabkit replay {bag.path} --scenario {scenario}`: the session's duration"
            f"{', start posture' if topics['targets'] else ''}{''.join(', ' + w for w in took)}, on {scenario.name}\n")
    tmp = path.with_name(f".{path.name}.part")
    tmp.write_text(head + yaml.safe_dump(doc, sort_keys=False, width=120, default_flow_style=None))
    tmp.replace(path)
    return path
