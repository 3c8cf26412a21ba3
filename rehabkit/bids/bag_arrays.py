"""A run's ROS 2 bag (``run.mcap``, :mod:`rehabkit.ros.bag`) as arrays at the rate it was recorded: every control
step's joint states, the reference, the interaction force and the person's wrench; a sensor's joint states or wrench
at its own rate; the few messages that mark the session (targets shown, the log).

Read with ``rosbags`` (its MCAP reader, ROS 2 Humble's type store), as the bag's other readers in rehabkit are.
Times are the messages' header stamps [ns] (a Float64's: its log time).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

JOINT_STATE, WRENCH, FLOAT64 = "sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped", "std_msgs/msg/Float64"
FEW = ("geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped", "rcl_interfaces/msg/Log")


@dataclass
class Stream:
    """A topic's samples: stamps [ns] and values (n, m); a JointState's joint ``names``; a message's frame."""

    topic: str
    stamps: np.ndarray
    values: np.ndarray
    names: list[str] = field(default_factory=list)
    frame: str = ""
    velocity: np.ndarray | None = None  # a JointState's, where its messages hold them
    effort: np.ndarray | None = None


@dataclass
class BagArrays:
    """What :func:`read_bag` found: the streams by topic, the few messages decoded (topic → [(stamp, message)]),
    each topic's type, and the bag's start (``/robot_description``'s time: the run's t = 0)."""

    streams: dict[str, Stream]
    messages: dict[str, list]
    types: dict[str, str]
    start_ns: int | None


def _stamp(m) -> int:
    return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec


class _Gather:
    """A topic's samples as they are read (only the numbers kept, not the messages: a 10-min session at 1 kHz is a
    million of them): stamps, and per field the values in the first message's joint order."""

    def __init__(self, topic: str, kind: str):
        self.topic, self.kind, self.stamps, self.names, self.frame = topic, kind, [], None, ""
        self.fields: dict[str, list] = {"position": [], "velocity": [], "effort": [], "values": []}

    def add(self, log_ns: int, m) -> None:
        if self.kind == FLOAT64:  # (no header: its log time is its stamp)
            self.stamps.append(log_ns)
            self.fields["values"].append((m.data,))
            return
        if self.names is None:
            self.names, self.frame = (list(m.name) if self.kind == JOINT_STATE else []), m.header.frame_id
        self.stamps.append(_stamp(m))
        if self.kind == WRENCH:
            f, t = m.wrench.force, m.wrench.torque
            self.fields["values"].append((f.x, f.y, f.z, t.x, t.y, t.z))
            return
        same = len(m.name) == len(self.names) and list(m.name) == self.names
        for name in ("position", "velocity", "effort"):
            a = getattr(m, name)
            if len(a) != len(m.name):
                self.fields[name] = None  # (not in every message: e.g. a reference's efforts)
                continue
            if self.fields[name] is None:
                continue
            self.fields[name].append(a if same else [a[list(m.name).index(n)] if n in m.name else np.nan
                                                       for n in self.names])

    def stream(self) -> Stream:
        def array(name: str) -> np.ndarray | None:
            rows = self.fields[name]
            if rows is None or len(rows) != len(self.stamps):
                return None
            return np.array(rows, float).reshape(len(rows), -1)

        stamps = np.array(self.stamps, np.int64)
        if self.kind == JOINT_STATE:
            return Stream(self.topic, stamps, array("position"), self.names, self.frame, array("velocity"),
                          array("effort"))
        return Stream(self.topic, stamps, array("values"), frame=self.frame)


def read_bag(path: Path) -> BagArrays:
    """Every JointState, WrenchStamped and Float64 topic of the bag as a :class:`Stream`; targets and the log as
    messages. Read with ``rosbags`` (its reader and ROS 2 Humble's type store). Raises ``ValueError`` where the file
    is not a bag that can be read."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    gathers: dict[str, _Gather] = {}
    messages: dict[str, list] = {}
    types: dict[str, str] = {}
    start_ns = None
    try:
        with AnyReader([Path(path)], default_typestore=store) as reader:
            for c in reader.connections:
                types[c.topic] = c.msgtype
            wanted = [c for c in reader.connections
                      if c.msgtype in (JOINT_STATE, WRENCH, FLOAT64, *FEW) or c.topic == "/robot_description"]
            for c, log_ns, data in reader.messages(connections=wanted):  # (in log-time order)
                if c.topic == "/robot_description":
                    start_ns = log_ns if start_ns is None else min(start_ns, log_ns)
                    continue
                m = store.deserialize_cdr(data, c.msgtype)
                if c.msgtype in (JOINT_STATE, WRENCH, FLOAT64):
                    gathers.setdefault(c.topic, _Gather(c.topic, c.msgtype)).add(log_ns, m)
                else:
                    messages.setdefault(c.topic, []).append((int(log_ns), m))
    except (AnyReaderError, OSError, struct.error, EOFError, KeyError) as exc:
        raise ValueError(str(exc) or type(exc).__name__) from exc
    streams = {topic: g.stream() for topic, g in gathers.items()}
    for s in streams.values():  # (time order by stamp)
        order = np.argsort(s.stamps, kind="stable")
        if not np.array_equal(order, np.arange(len(order))):
            s.stamps, s.values = s.stamps[order], s.values[order]
            s.velocity = s.velocity[order] if s.velocity is not None else None
            s.effort = s.effort[order] if s.effort is not None else None
    return BagArrays(streams, messages, types, start_ns)
