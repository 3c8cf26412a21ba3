"""The scenario a recorded session is replayed in: the user's scenario, with the session's start posture, duration,
targets as they were shown (each at its time, a replan to it) and its person (their recorded wrench) put in.

It is written as a file that ``extends:`` the user's (``replayed_session.yaml`` in the replay's folder), so what ran
can be read, validated and run again, and an error in it is located like any other.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import yaml

from rehabkit.ros.bag_content import BagError, Remark, Where
from rehabkit.ros.session_bag import SessionBag, ShownTarget

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
    """The ``task:`` section: start where the session started, then a replan to each target when it was shown
    (``timed``: the planner is timed by ``segment_durations``, one per target: each replan's is the time until the
    next target was shown, or the session's end)."""
    import pinocchio as pin

    model = robot.model
    order = joint_order(bag, list(model.joint_names))
    start = bag.joints.values[0, order]
    targets: list[dict] = [{"name": "start", "joints_rad": [float(v) for v in start]}]
    events = []
    shown_all = shown_targets(bag)
    until = [t.t for t in shown_all[1:]] + [bag.duration_s]
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
        # (a timed planner plans through its via points: from the target before, where the robot should be)
        event = {"at": round(float(shown.t), 9), "action": "replan",
                 "sequence": [f"shown_{i}" if i else "start", name] if timed else [name]}
        if timed:
            event["planner"] = {"segment_durations": [round(max(until[i] - shown.t, 1e-3), 9)]}
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
