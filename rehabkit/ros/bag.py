"""A run as a ROS 2 bag (MCAP, ROS 2's default storage since Iron; written as the run goes by
:mod:`rehabkit.ros.bag_writer`): what Foxglove, PlotJuggler and ``ros2 bag`` open.

Topics: ``/robot_description`` (std_msgs/String, the URDF), ``/tf_static`` and ``/tf`` (the description's joint tree
as ``robot_state_publisher`` publishes it, and where the scenario put the robot: :mod:`rehabkit.ros.tf_tree`),
``/joint_states`` (sensor_msgs/JointState: the measured joints and the torque sent, every control step, as the
trace has them), ``/reference/joint_states`` (the reference), ``/interaction_force`` (std_msgs/Float64, where the run
measured one), ``/wrench`` (geometry_msgs/WrenchStamped: a person's wrench at the hand, where there is one),
``/targets`` (each movement's goal as it began, where it is one for the hand: PointStamped, or PoseStamped where a
target of the task sets the hand's orientation) and ``/targets/joint_states`` (sensor_msgs/JointState: a posture
target's joint values, as it began), every sensor's readings under ``/sensors/<name>/``
(:mod:`rehabkit.ros.bag_sensors`), ``/rosout`` (rcl_interfaces/Log: the safety layer's events and interventions, the
run's notes). ``rehabkit replay run.mcap --scenario S.yaml`` replays it as it would a robot's.
Stamps: the run's start (``start_ns``, the Unix epoch; a replay's: the recorded session's) plus the run's own time.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from rehabkit.core.kinds.capabilities import BaseState
from rehabkit.core.plugins.lifecycle import RunInfo, RunTap
from rehabkit.models.hand_force import least_wrenches
from rehabkit.ros.bag_sensors import reading_messages
from rehabkit.ros.bag_writer import BagWriter
from rehabkit.ros.tf_tree import TfTree, Transform

LOG_LEVEL = {"DEBUG": 10, "INFO": 20, "WARN": 30, "ERROR": 40, "FATAL": 50}
FLUSH_EVERY_S = 1.0  # the bag's messages reach the file at least this often (wall time): what a killed run loses


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _xyz(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(r: np.ndarray) -> dict:
    import pinocchio as pin

    q = pin.Quaternion(np.asarray(r, float))
    q.normalize()
    return {"x": q.x, "y": q.y, "z": q.z, "w": q.w}


def _transform(t: Transform, ns: int) -> dict:
    m = t.matrix
    return {"header": {"stamp": _stamp(ns), "frame_id": t.parent}, "child_frame_id": t.child,
            "transform": {"translation": _xyz(m[:3, 3]), "rotation": _quat(m[:3, :3])}}


def _ros_frame(frame: str | None, base: str) -> str:
    """A sensor's frame as tf names it: a body's name as it is, the robot base as the robot's base link."""
    return base if frame in (None, "", "robot base", "base") else frame


class BagRecorder(RunTap):
    """The run's bag as it goes: opened with the session (``.run.mcap.part``), each sensor reading as it is taken,
    the trace's topics at each logged step for the rows run since (once the session lets it :meth:`follow` the
    trace), the chunk under way written out at least every :data:`FLUSH_EVERY_S` of wall time — a killed run's bag
    reads up to there (``rehabkit recover`` indexes it) — and the rest when the run is over (:meth:`finish`, then
    renamed to ``run.mcap``); dropped if the run fails before its loop."""

    def __init__(self, path: Path, run: RunInfo, start_ns: int, description: str):
        self.path, self.start_ns = path, start_ns
        self.part = path.with_name(f".{path.name}.part")
        robot = run.robot.model
        # a floating robot's root moves: its pose in the world at the log rate, as the backend reports it
        self._root = run.backend.base_state if robot.floating and isinstance(run.backend, BaseState) else None
        hand = robot.pin_model.frames[robot.ee_frame_id].name  # (the frame /wrench is given in)
        frames = [hand, *(s.frame for s in run.sensors.values() if isinstance(s.frame, str))]
        try:
            self.tree = TfTree(description, robot, frames, floating=self._root is not None)
        except ValueError:  # (a description whose tree can't be read as one: the model's own, as a URDF)
            from rehabkit.ros.description import urdf_from_model

            self.tree = TfTree(urdf_from_model(robot.pin_model, robot.name, robot.limits), robot, frames,
                               floating=self._root is not None)
        self.base = self.tree.base
        self.bag = BagWriter(self.part)
        self._frames = {name: _ros_frame(s.frame, self.base) for name, s in run.sensors.items()}
        self._channels = {name: s.channels for name, s in run.sensors.items()}
        self._names, self._model, self._hand = list(robot.joint_names), robot.pin_model, robot.ee_frame_id
        self._every = max(1, run.schedule.log_every)
        self._trace = None  # the session's trace, as the loop fills it (:meth:`follow`)
        self._movements = None  # ... and its movements so far
        self._moves_done = 0  # the movements whose target is in the bag
        self._run = run
        self._sensed = {spec.name for spec in run.scenario.task.targets if spec.sensor}
        self._rows_done = 0  # the trace's rows in the bag
        self._tf_next = 0  # the next logged step whose /tf is due
        self._flush_by = time.monotonic() + FLUSH_EVERY_S
        self.bag.put("/robot_description", "std_msgs/String", {"data": description}, start_ns)
        self.bag.put("/tf_static", "tf2_msgs/TFMessage",
                     {"transforms": [_transform(t, start_ns) for t in self.tree.static()]}, start_ns)

    def _ns(self, t: float) -> int:
        return self.start_ns + round(t * 1e9)

    def follow(self, trace, movements) -> None:
        self._trace, self._movements = trace, movements

    def logged(self, t: float, k: int) -> None:
        tr = self._trace
        if tr is None or k < self._rows_done:  # (not followed; or a session restored to an earlier step)
            return
        _rows(self.bag, tr, self._rows_done, k + 1, self.start_ns, self._names, self._model, self._hand)
        self._rows_done = k + 1
        root = None
        if self._root is not None:
            import pinocchio as pin

            position, (w, x, y, z), _, _ = self._root()
            root = np.eye(4)
            root[:3, :3], root[:3, 3] = pin.Quaternion(w, x, y, z).toRotationMatrix(), position
        self._tf(k, t, tr.q[k], root)
        self._targets(self._movements(), k, tr.t)
        if time.monotonic() >= self._flush_by:
            self._flush_by = time.monotonic() + FLUSH_EVERY_S
            self.bag.flush()

    def _tf(self, k: int, t: float, q: np.ndarray, root: np.ndarray | None) -> None:
        at = self._ns(t)
        moved = self.tree.moving(q, root)
        self.bag.put("/tf", "tf2_msgs/TFMessage", {"transforms": [_transform(m, at) for m in moved]}, at)
        self._tf_next = k + self._every

    def _targets(self, movements, k: int, t: np.ndarray) -> None:
        """The goal of each movement begun by step ``k`` not yet in the bag (a movement begun is final: a replan
        replaces only those not yet begun)."""
        while self._moves_done < len(movements) and movements[self._moves_done].k0 <= k:
            mv = movements[self._moves_done]
            if mv.k0 < len(t):
                _target(self.bag, self._run, mv, self._ns(float(t[mv.k0])), self.tree, self._sensed)
            self._moves_done += 1

    def reading(self, t: float, name: str, reading: dict) -> None:
        ns = self._ns(t)
        header = {"stamp": _stamp(ns), "frame_id": ""}
        seen = reading.get("target_position")
        if seen is not None and not np.allclose(self.tree.base_to_frame, np.eye(4)):  # (in the bag's base frame)
            m = self.tree.base_to_frame
            reading = {**reading, "target_position": m[:3, :3] @ np.asarray(seen, float) + m[:3, 3]}
        for topic, msg_type, message in reading_messages(name, reading, header, self._frames[name],
                                                         self._channels[name], self.base):
            self.bag.put(topic, msg_type, message, ns)

    def discard(self) -> None:
        self.bag.file.close()
        self.part.unlink(missing_ok=True)

    def finish(self, run: RunInfo, record) -> dict:
        """The rest of the trace's topics, the targets and ``/rosout``; the bag closed and renamed; returns its topics
        with their types and message counts."""
        try:
            tr = record.trace
            _rows(self.bag, tr, self._rows_done, len(tr.t), self.start_ns, self._names, self._model, self._hand)
            for k in range(self._tf_next, len(tr.t), self._every):  # (the steps the loop did not log: a stop's)
                self._tf(k, float(tr.t[k]), tr.q[k], None)
            self._targets(record.movements, len(tr.t) - 1, tr.t)
            _rosout(self.bag, record, self.start_ns)
            self.bag.finish()
            os.replace(self.part, self.path)
        except BaseException:
            self.discard()
            raise
        bag = self.bag
        return {topic: {"type": bag.types[topic], "messages": n} for topic, n in sorted(bag.counts.items())}


TARGETS = {"point": ("/targets", "geometry_msgs/PointStamped"), "pose": ("/targets/pose", "geometry_msgs/PoseStamped"),
           "joints": ("/targets/joint_states", "sensor_msgs/JointState")}  # a target's topic and type, by kind


def _target(bag: BagWriter, run: RunInfo, mv, at: int, tree: TfTree, sensed: set[str]) -> None:
    """A movement's goal as it began, by what its target gives (:data:`TARGETS`): a posture's joint values as the
    task gives them, a hand pose (a position and the orientation the hand must take; as the plan reaches it where
    some axes are free), or where the hand goes; in the bag's base frame (``sensed``: the targets a sensor places,
    whose position is the movement's)."""
    robot = run.robot.model
    names, m = list(robot.joint_names), tree.base_to_frame
    header = {"stamp": _stamp(at), "frame_id": tree.base}
    target = run.targets.get(mv.name) if mv.name is not None else None
    if target is not None and target.q is not None:  # (a posture stays one: a replay reaches it, not an IK's)
        topic, msg_type = TARGETS["joints"]
        bag.put(topic, msg_type, {"header": {**header, "frame_id": ""}, "name": names,
                                  "position": [float(v) for v in target.q], "velocity": [], "effort": []}, at)
    elif target is not None and target.pose is not None and not target.position_only:
        pose = m @ (target.pose if not target.free_axes else robot.ee_pose(np.asarray(mv.target, float)))
        topic, msg_type = TARGETS["pose"]
        bag.put(topic, msg_type, {"header": header, "pose": {"position": _xyz(pose[:3, 3]),
                                                             "orientation": _quat(pose[:3, :3])}}, at)
    else:
        goal = target.pose[:3, 3] if target is not None and target.pose is not None and mv.name not in sensed \
            else np.asarray(mv.goal, float)
        topic, msg_type = TARGETS["point"]
        bag.put(topic, msg_type, {"header": header, "point": _xyz(m[:3, :3] @ goal + m[:3, 3])}, at)


def _rows(bag: BagWriter, tr, a: int, b: int, start_ns: int, names: list[str], model, hand: int) -> None:
    """The trace's rows ``a:b``: the joint states, the reference, the interaction force and the person's wrench at
    the hand (in its axes: the least one whose joint torques are theirs)."""
    if b <= a:
        return
    ns = start_ns + np.rint(tr.t[a:b] * 1e9).astype(np.int64)
    q, qd, tau, q_ref, qd_ref = tr.q[a:b], tr.qd[a:b], tr.tau[a:b], tr.q_ref[a:b], tr.qd_ref[a:b]
    referenced = np.isfinite(q_ref).all(axis=1)
    force = tr.f_h[a:b] if tr.f_h is not None else None
    # (every step where there is a simulated person: a push of nothing is a wrench of zero)
    wrenches = least_wrenches(model, q, tr.tau_h[a:b], hand) if tr.tau_h is not None else None
    frame = model.frames[hand].name
    for i in range(b - a):
        at = int(ns[i])
        stamp = {"stamp": _stamp(at), "frame_id": ""}
        bag.put("/joint_states", "sensor_msgs/JointState",
                {"header": stamp, "name": names, "position": q[i], "velocity": qd[i], "effort": tau[i]}, at)
        if referenced[i]:
            bag.put("/reference/joint_states", "sensor_msgs/JointState",
                    {"header": stamp, "name": names, "position": q_ref[i], "velocity": qd_ref[i]}, at)
        if force is not None and np.isfinite(force[i]):
            bag.put("/interaction_force", "std_msgs/Float64", {"data": float(force[i])}, at)
        if wrenches is not None:
            w = wrenches[i]
            bag.put("/wrench", "geometry_msgs/WrenchStamped",
                    {"header": {**stamp, "frame_id": frame}, "wrench": {"force": _xyz(w[:3]), "torque": _xyz(w[3:])}},
                    at)


def _rosout(bag: BagWriter, record, start_ns: int) -> None:
    """The safety layer's events and interventions and the run's notes, in time order."""
    events = list(record.safety.events)
    said = [(e.t, "ERROR", f"SAFETY {e.message}") for e in events]
    trips = {(e.t, e.rule) for e in events}  # (each trip is among the interventions too: said once)
    said += [(e.t, e.level, f"SAFETY {e.message}") for e in record.interventions if (e.t, e.rule) not in trips]
    said += [(n["t"], "INFO", n["text"]) for n in record.notes]
    for t, level, text in sorted(said, key=lambda x: x[0]):
        when = start_ns + round(t * 1e9)
        bag.put("/rosout", "rcl_interfaces/Log", {"stamp": _stamp(when), "level": LOG_LEVEL.get(level, 20),
                                                 "name": "rehabkit", "msg": text, "file": "", "function": "",
                                                 "line": 0}, when)
