"""A run as a ROS 2 bag (MCAP, ROS 2's default storage since Iron; written with the ``mcap`` library's ROS 2 support):
what Foxglove, PlotJuggler and ``ros2 bag`` open.

Topics: ``/robot_description`` (std_msgs/String, the URDF), ``/tf_static`` (world → base_link) and ``/tf`` (each
link from its parent, at the log rate: tf2_msgs/TFMessage, as ``robot_state_publisher`` publishes them),
``/joint_states`` (sensor_msgs/JointState: the measured joints and the torque sent, every control step, as the
trace has them), ``/reference/joint_states`` (the reference), ``/interaction_force`` (std_msgs/Float64, where the run
measured one), ``/wrench`` (geometry_msgs/WrenchStamped: a person's wrench at the hand, where there is one),
``/targets`` (geometry_msgs/PointStamped: each movement's goal as it began), every sensor's readings under
``/sensors/<name>/`` (:mod:`rehabkit.ros.bag_sensors`), ``/rosout`` (rcl_interfaces/Log: the safety layer's events
and interventions, the run's notes). ``rehabkit replay run.mcap --scenario S.yaml`` replays it as it would a robot's.
Stamps: the run's start (``start_ns``, the Unix epoch) plus the run's own time.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np

from rehabkit.core.kinds.capabilities import BaseState
from rehabkit.core.plugins.lifecycle import RunTap
from rehabkit.models.hand_force import least_wrenches
from rehabkit.ros.bag_sensors import reading_messages
from rehabkit.ros.description import base_frame, links, relative
from rehabkit.ros.msgdefs import datatype, msgdef

LOG_LEVEL = {"DEBUG": 10, "INFO": 20, "WARN": 30, "ERROR": 40, "FATAL": 50}


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _xyz(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _transform(parent: str, child: str, ns: int, m: np.ndarray) -> dict:
    import pinocchio as pin

    quat = pin.Quaternion(m[:3, :3])
    return {"header": {"stamp": _stamp(ns), "frame_id": parent}, "child_frame_id": child,
            "transform": {"translation": dict(zip("xyz", map(float, m[:3, 3]), strict=True)),
                          "rotation": {"x": quat.x, "y": quat.y, "z": quat.z, "w": quat.w}}}


class _Bag:
    def __init__(self, path: Path):
        from mcap_ros2.writer import Writer

        self.file = open(path, "wb")  # noqa: SIM115 (closed in finish)
        self.writer = Writer(self.file)
        self.schemas: dict[str, object] = {}
        self.counts: Counter = Counter()
        self.types: dict[str, str] = {}

    def put(self, topic: str, msg_type: str, message: dict, ns: int) -> None:
        if msg_type not in self.schemas:
            self.schemas[msg_type] = self.writer.register_msgdef(datatype(msg_type), msgdef(msg_type))
        self.writer.write_message(topic, self.schemas[msg_type], message, log_time=ns, publish_time=ns,
                                  sequence=self.counts[topic])
        self.counts[topic] += 1
        self.types[topic] = datatype(msg_type)

    def finish(self) -> None:
        self.writer.finish()
        self.file.close()


def _ros_frame(frame: str | None, base: str) -> str:
    """A sensor's frame as tf names it: a body's name as it is, the robot base as the robot's base link."""
    return base if frame in (None, "", "robot base", "base") else frame


class BagRecorder(RunTap):
    """The run's bag as it goes: opened with the session (``.run.mcap.part``), each sensor reading as it is taken,
    a floating robot's root at the log rate, the trace's topics when the run is over (:meth:`finish`, then renamed to
    ``run.mcap``); dropped if the run fails."""

    def __init__(self, path: Path, setup, start_ns: int, description: str):
        import pinocchio as pin

        self.path, self.start_ns = path, start_ns
        self.part = path.with_name(f".{path.name}.part")
        self.bag = _Bag(self.part)
        robot = setup.robot.model
        model = robot.pin_model
        self.links, self.base = links(model), base_frame(model)
        self._frames = {name: _ros_frame(s.frame, self.base) for name, s in setup.sensors.items()}
        self._channels = {name: s.channels for name, s in setup.sensors.items()}
        # a floating robot's root moves: its pose in the world at the log rate, as the backend reports it
        self._root = setup.backend.base_state if robot.floating and isinstance(setup.backend, BaseState) else None
        self.roots: dict[int, np.ndarray] = {}  # logged control step → the root's pose
        self.bag.put("/robot_description", "std_msgs/String", {"data": description}, start_ns)
        data = model.createData()
        pin.framesForwardKinematics(model, data, pin.neutral(model))
        world = np.asarray(robot.base_pose, float)
        fixed = [_transform(model.frames[link.parent].name, link.name, start_ns, relative(data, link))
                 for link in self.links if link.parent is not None and not link.moving]
        fixed += [_transform("world", link.name, start_ns, world @ relative(data, link)) for link in self.links
                  if link.parent is None and not link.moving and self._root is None]
        hand = model.frames[robot.ee_frame_id]
        if hand.name not in {link.name for link in self.links}:  # (a site: the frame /wrench is given in)
            body = max(link.frame for link in self.links if link.frame < robot.ee_frame_id
                       and model.frames[link.frame].parentJoint == hand.parentJoint)
            fixed.append(_transform(model.frames[body].name, hand.name, start_ns,
                                    data.oMf[body].actInv(data.oMf[robot.ee_frame_id]).homogeneous))
        self.bag.put("/tf_static", "tf2_msgs/TFMessage", {"transforms": fixed}, start_ns)

    def logged(self, t: float, k: int) -> None:
        if self._root is not None:
            import pinocchio as pin

            position, (w, x, y, z), _, _ = self._root()
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = pin.Quaternion(w, x, y, z).toRotationMatrix(), position
            self.roots[k] = pose

    def reading(self, t: float, name: str, reading: dict) -> None:
        ns = self.start_ns + round(t * 1e9)
        header = {"stamp": _stamp(ns), "frame_id": ""}
        for topic, msg_type, message in reading_messages(name, reading, header, self._frames[name],
                                                         self._channels[name], self.base):
            self.bag.put(topic, msg_type, message, ns)

    def discard(self) -> None:
        self.bag.file.close()
        self.part.unlink(missing_ok=True)

    def finish(self, setup, record) -> dict:
        """The trace's topics, the bag closed and renamed; returns its topics with their types and message counts."""
        try:
            _trace_topics(self.bag, setup, record, self.start_ns, self)
            self.bag.finish()
            os.replace(self.part, self.path)
        except BaseException:
            self.discard()
            raise
        bag = self.bag
        return {topic: {"type": bag.types[topic], "messages": n} for topic, n in sorted(bag.counts.items())}


def _kind(spec, specs) -> str:
    """What a task target gives: ``joints``, a ``pose`` (a position and an orientation) or a ``point``."""
    if spec.same_as is not None:
        return _kind(next(s for s in specs if s.name == spec.same_as), specs)
    if spec.joints_deg is not None or spec.joints_rad is not None:
        return "joints"
    return "pose" if spec.rpy_deg is not None or spec.orientation_of is not None else "point"


def _trace_topics(bag: _Bag, setup, record, start_ns: int, tree: BagRecorder) -> None:
    """Joint states, reference, the person's wrench and the interaction force every control step, the targets as
    each movement began, tf at the log rate, the safety layer's events and the notes."""
    import pinocchio as pin

    tr, robot = record.trace, setup.robot.model
    names = list(robot.joint_names)
    ns = start_ns + np.rint(tr.t * 1e9).astype(np.int64)
    person = tr.tau_h is not None and len(tr.t) and np.any(tr.tau_h)
    model = robot.pin_model
    data, hand = model.createData(), robot.ee_frame_id
    # the person's wrench at the hand, in its axes: the least one whose joint torques are theirs
    wrenches = least_wrenches(model, tr.q, tr.tau_h, hand) if person else None
    for k in range(len(tr.t)):
        stamp = {"stamp": _stamp(int(ns[k])), "frame_id": ""}
        bag.put("/joint_states", "sensor_msgs/JointState",
                {"header": stamp, "name": names, "position": tr.q[k].tolist(), "velocity": tr.qd[k].tolist(),
                 "effort": tr.tau[k].tolist()}, int(ns[k]))
        if np.isfinite(tr.q_ref[k]).all():
            bag.put("/reference/joint_states", "sensor_msgs/JointState",
                    {"header": stamp, "name": names, "position": tr.q_ref[k].tolist(),
                     "velocity": tr.qd_ref[k].tolist(), "effort": []}, int(ns[k]))
        if tr.f_h is not None and np.isfinite(tr.f_h[k]):
            bag.put("/interaction_force", "std_msgs/Float64", {"data": float(tr.f_h[k])}, int(ns[k]))
        if person:
            w = wrenches[k]
            bag.put("/wrench", "geometry_msgs/WrenchStamped",
                    {"header": {**stamp, "frame_id": model.frames[hand].name},
                     "wrench": {"force": _xyz(w[:3]), "torque": _xyz(w[3:])}}, int(ns[k]))
    # the targets as the task gave them: joint values where every target is a posture, the hand's pose where one
    # sets its orientation (as the joint-space plan reaches it), else where the hand goes
    kinds = {_kind(spec, setup.sc.task.targets) for spec in setup.sc.task.targets}
    in_joints, oriented = kinds == {"joints"}, "pose" in kinds
    for mv in record.movements:
        if mv.k0 >= len(tr.t):
            continue
        stamp, at = {"stamp": _stamp(int(ns[mv.k0])), "frame_id": tree.base}, int(ns[mv.k0])
        if in_joints:
            bag.put("/targets", "sensor_msgs/JointState", {"header": stamp, "name": names, "position": [
                float(v) for v in mv.target], "velocity": [], "effort": []}, at)
        elif oriented and len(mv.target) == robot.dof:
            pose = robot.ee_pose(np.asarray(mv.target, float))
            r = pin.Quaternion(pose[:3, :3])
            bag.put("/targets", "geometry_msgs/PoseStamped", {"header": stamp, "pose": {
                "position": _xyz(pose[:3, 3]), "orientation": {"x": r.x, "y": r.y, "z": r.z, "w": r.w}}}, at)
        else:
            bag.put("/targets", "geometry_msgs/PointStamped", {"header": stamp, "point": _xyz(mv.goal)}, at)
    world, moving = np.asarray(robot.base_pose, float), [link for link in tree.links if link.moving]
    every = max(1, setup.schedule.log_every)
    for k in range(0, len(tr.t), every):
        pin.framesForwardKinematics(model, data, tr.q[k])
        moved = [_transform(model.frames[link.parent].name if link.parent is not None else "world", link.name,
                            int(ns[k]), relative(data, link) if link.parent is not None else world @ relative(data,
                                                                                                         link))
                 for link in moving]
        if (root := tree.roots.get(k)) is not None:  # (a floating robot's root, at the logged steps)
            moved += [_transform("world", link.name, int(ns[k]), root @ relative(data, link))
                      for link in tree.links if link.parent is None]
        bag.put("/tf", "tf2_msgs/TFMessage", {"transforms": moved}, int(ns[k]))
    events = list(setup.safety.events)
    said = [(e.t, "ERROR", f"SAFETY {e.message}") for e in events]
    trips = {(e.t, e.rule) for e in events}  # (each trip is among the interventions too: said once)
    said += [(e.t, e.level, f"SAFETY {e.message}") for e in record.interventions if (e.t, e.rule) not in trips]
    said += [(n["t"], "INFO", n["text"]) for n in record.notes]
    for t, level, text in sorted(said, key=lambda x: x[0]):
        when = start_ns + round(t * 1e9)
        bag.put("/rosout", "rcl_interfaces/Log", {"stamp": _stamp(when), "level": LOG_LEVEL.get(level, 20),
                                                 "name": "rehabkit", "msg": text, "file": "", "function": "",
                                                 "line": 0}, when)
