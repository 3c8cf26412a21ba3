"""A run as a ROS 2 bag (MCAP, ROS 2's default storage since Iron; written with the ``mcap`` library's ROS 2 support):
what Foxglove, PlotJuggler and ``ros2 bag`` open.

Topics: ``/robot_description`` (std_msgs/String, the URDF), ``/tf_static`` (world → base_link) and ``/tf`` (each
link from its parent, at the log rate: tf2_msgs/TFMessage, as ``robot_state_publisher`` publishes them),
``/joint_states`` (sensor_msgs/JointState: the measured joints and the torque sent, every control step, as the
trace has them), ``/reference/joint_states`` (the reference), ``/interaction_force`` (std_msgs/Float64, where the run
measured one), ``/rosout`` (rcl_interfaces/Log: the safety layer's events and interventions, the run's notes).
Stamps: the run's start (``start_ns``, the Unix epoch) plus the run's own time.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np

from rehabkit.ros.description import link_names
from rehabkit.ros.msgdefs import datatype, msgdef

LOG_LEVEL = {"DEBUG": 10, "INFO": 20, "WARN": 30, "ERROR": 40, "FATAL": 50}


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


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


def write_bag(path: Path, setup, record, start_ns: int, description: str) -> dict:
    """``path`` (written whole: a temporary name, renamed) from the finished run; returns its topics with their types
    and message counts."""
    import pinocchio as pin

    tr, robot = record.trace, setup.robot.model
    names = list(robot.joint_names)
    part = path.with_name(f".{path.name}.part")
    bag = _Bag(part)
    try:
        bag.put("/robot_description", "std_msgs/String", {"data": description}, start_ns)
        bag.put("/tf_static", "tf2_msgs/TFMessage",
                {"transforms": [_transform("world", "base_link", start_ns, np.asarray(robot.base_pose, float))]},
                start_ns)
        ns = start_ns + np.rint(tr.t * 1e9).astype(np.int64)
        empty = {"frame_id": ""}
        for k in range(len(tr.t)):
            stamp = {**empty, "stamp": _stamp(int(ns[k]))}
            bag.put("/joint_states", "sensor_msgs/JointState",
                    {"header": stamp, "name": names, "position": tr.q[k].tolist(), "velocity": tr.qd[k].tolist(),
                     "effort": tr.tau[k].tolist()}, int(ns[k]))
            if np.isfinite(tr.q_ref[k]).all():
                bag.put("/reference/joint_states", "sensor_msgs/JointState",
                        {"header": stamp, "name": names, "position": tr.q_ref[k].tolist(),
                         "velocity": tr.qd_ref[k].tolist(), "effort": []}, int(ns[k]))
            if tr.f_h is not None and np.isfinite(tr.f_h[k]):
                bag.put("/interaction_force", "std_msgs/Float64", {"data": float(tr.f_h[k])}, int(ns[k]))
        model = robot.pin_model
        data, links = model.createData(), link_names(model)
        every = max(1, setup.schedule.log_every)
        for k in range(0, len(tr.t), every):
            pin.forwardKinematics(model, data, tr.q[k])
            bag.put("/tf", "tf2_msgs/TFMessage", {"transforms": [
                _transform(links[model.parents[j]], links[j], int(ns[k]), data.liMi[j].homogeneous)
                for j in range(1, model.njoints)]}, int(ns[k]))
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
        bag.finish()
        os.replace(part, path)
    except BaseException:
        bag.file.close()
        part.unlink(missing_ok=True)
        raise
    return {topic: {"type": bag.types[topic], "messages": n} for topic, n in sorted(bag.counts.items())}
