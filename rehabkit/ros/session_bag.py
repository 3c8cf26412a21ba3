"""A session recorded on a robot, read from its ROS bag: the joints, the person's wrench, the targets as shown.

The bag is read with ``rosbags`` (ROS 2 bags in MCAP or SQLite, a folder with ``metadata.yaml`` or a bare ``.mcap``
file, and ROS 1 bags). Each role is a topic (``/joint_states``, ``/wrench``, ``/targets`` unless renamed); its times
are the messages' header stamps (the log time where a stamp is zero), from the first joint state on. A stretch
without messages much longer than the topic's usual period is a :class:`Gap`: said, and bridged by interpolation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError

TOPICS = {"joint_states": "/joint_states", "wrench": "/wrench", "targets": "/targets"}
TYPES = {"joint_states": ("sensor_msgs/msg/JointState",),
         "wrench": ("geometry_msgs/msg/WrenchStamped",),
         "targets": ("geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/JointState")}
FIX = {"joint_states": "name the joint states' topic: --topics joint_states=TOPIC",
       "wrench": "name the person's wrench topic: --topics wrench=TOPIC; or --topics wrench= to replay without it, "
                 "the scenario's own patient (if any) in the robot",
       "targets": "name the targets' topic: --topics targets=TOPIC; or --topics targets= to replay without them, "
                  "on the scenario's own task"}
GAP_PERIODS = 5.0  # a stretch this many usual periods long without a message is a gap
GAP_MIN_S = 0.05  # ... and at least this long (a 1 kHz topic missing 6 ms is jitter, not a gap)


@dataclass(frozen=True)
class Gap:
    """Where a topic has no messages: from ``start_s`` (session time) for ``length_s``."""

    topic: str
    start_s: float
    length_s: float

    def __str__(self) -> str:
        return f"{self.topic} has no messages for {self.length_s:.3f} s from t = {self.start_s:.3f} s"


@dataclass
class Series:
    """A topic's samples: times [s] from the session's start, values (n, m), and the frame they are given in."""

    topic: str
    t: np.ndarray
    values: np.ndarray
    frame: str = ""
    names: list[str] = field(default_factory=list)  # a JointState's joint names

    def at(self, t: np.ndarray) -> np.ndarray:
        """The values at times ``t``, linear between samples, held at either end."""
        return np.stack([np.interp(t, self.t, self.values[:, i]) for i in range(self.values.shape[1])], axis=1)


@dataclass
class ShownTarget:
    """A target as it was shown: at ``t`` [s], a point [m] (``kind`` ``point``), a pose (position and quaternion
    x, y, z, w: ``pose``) in ``frame``, or joint values [rad] (``joints``, in the order of ``names``)."""

    t: float
    kind: str
    values: np.ndarray
    frame: str = ""
    names: list[str] = field(default_factory=list)


@dataclass
class SessionBag:
    """What the bag holds for a replay; ``joints`` names, ``position``/``velocity``/``effort`` their samples (the
    last two None where the messages leave them empty)."""

    path: Path
    joints: Series
    velocity: Series | None
    effort: Series | None
    wrench: Series | None
    targets: list[ShownTarget]
    gaps: list[Gap]

    @property
    def duration_s(self) -> float:
        """How long the session lasted: to its last joint state, and that sample's period."""
        return float(self.joints.t[-1] + np.median(np.diff(self.joints.t)))


class BagError(ScenarioError):
    """A bag that can't be replayed as asked: the ``bag``, the topic ``role`` concerned ('' for the whole bag), and
    what is wrong with the fix (``what``); said at the bag, naming the ``--topics`` role."""

    def __init__(self, bag: Path | str, role: str, what: str, more: list[tuple[str, str]] = ()):
        self.bag, self.role, self.what = str(bag), role, what
        self.problems = [(role, what), *more]  # every role's, said at once
        super().__init__([Diagnostic(Mark(str(bag), 0, 0), f"--topics {r}" if r else "", w)
                          for r, w in self.problems])





def parse_topics(items: list[str]) -> dict[str, str]:
    """``ROLE=TOPIC`` items (each may hold several, comma-separated) over the defaults; ``ROLE=`` for none (the
    wrench or the targets: the replay keeps the scenario's own person or task)."""
    topics = dict(TOPICS)
    for item in items:
        for pair in filter(None, item.split(",")):
            role, sep, topic = pair.partition("=")
            if not sep or role.strip() not in TOPICS or (role.strip() == "joint_states" and not topic.strip()):
                raise BagError("--topics", "", f"'{pair}': give ROLE=TOPIC with ROLE one of {', '.join(TOPICS)} "
                                                f"(e.g. --topics wrench=/cuff/wrench; wrench= or targets= for none)")
            topics[role.strip()] = topic.strip()
    return topics


def _stamp_ns(msg, log_ns: int) -> int:
    """A message's header stamp [ns], or the bag's log time where it has none."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    ns = stamp.sec * 1_000_000_000 + stamp.nanosec if stamp is not None else 0
    return ns if ns > 0 else log_ns


def _vec(v) -> list[float]:
    return [v.x, v.y, v.z]


def _gaps(topic: str, t: np.ndarray) -> list[Gap]:
    if len(t) < 3:
        return []
    dt = np.diff(t)
    usual = float(np.median(dt))
    long = np.flatnonzero(dt > max(GAP_PERIODS * usual, GAP_MIN_S))
    return [Gap(topic, float(t[i]), float(dt[i])) for i in long]


def read_session(path: str | Path, topics: dict[str, str] | None = None,
                 roles: tuple[str, ...] = tuple(TOPICS)) -> SessionBag:
    """The joints, wrench and targets of the bag at ``path`` (topics by role, :data:`TOPICS` unless named; only the
    ``roles`` asked for are read, the joint states always).

    Raises:
        BagError: the bag can't be read, a topic is missing or of another type, or joint states are empty.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path, topics = Path(path), {**TOPICS, **(topics or {})}
    topics = {role: topic for role, topic in topics.items() if (role in roles or role == "joint_states") and topic}
    if not path.exists():
        raise BagError(path, "", "no such bag (a rosbag2 folder with metadata.yaml, an .mcap file, or a ROS 1 .bag)")
    raw: dict[str, list] = {role: [] for role in TOPICS}
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            have = {c.topic: c.msgtype for c in reader.connections}
            listing = ", ".join(f"{t} ({m})" for t, m in sorted(have.items()))
            problems = []
            for role, topic in topics.items():
                if topic not in have:
                    problems.append((role, f"no topic {topic}; the bag has {listing} ({FIX[role]})"))
                elif have[topic] not in TYPES[role]:
                    problems.append((role, f"{topic} is {have[topic]}; {role} must be {' or '.join(TYPES[role])}"))
            if problems:
                raise BagError(path, *problems[0], more=problems[1:])
            wanted = {topics[r]: r for r in topics if topics[r] in have}
            conns = [c for c in reader.connections if c.topic in wanted]
            for conn, log_ns, data in reader.messages(connections=conns):
                msg = reader.deserialize(data, conn.msgtype)
                raw[wanted[conn.topic]].append((_stamp_ns(msg, log_ns), conn.msgtype, msg))
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors: a damaged or unknown file
        raise BagError(path, "", f"can't be read as a ROS bag: {exc}") from exc
    return _session(path, topics, raw)


def _session(path: Path, topics: dict[str, str], raw: dict[str, list]) -> SessionBag:
    js = sorted(raw["joint_states"], key=lambda r: r[0])
    if len(js) < 2:
        raise BagError(path, "joint_states", f"{topics['joint_states']} has {len(js)} message(s); a replay needs the "
                                              "session's joint states")
    names = list(js[0][2].name)
    t0 = js[0][0]
    t = np.array([(r[0] - t0) * 1e-9 for r in js])
    keep = np.concatenate([[True], np.diff(t) > 0])  # a repeated stamp: the first message counts
    rows = [r for r, k in zip(js, keep) if k]
    t = t[keep]
    changed = [i for i, r in enumerate(rows) if list(r[2].name) != names]
    if changed:
        raise BagError(path, "joint_states", f"message {changed[0]} names joints {list(rows[changed[0]][2].name)}, "
                                              f"the first {names}: a replay needs one joint order")

    def field_series(attr: str) -> Series | None:
        if any(len(getattr(r[2], attr)) != len(names) for r in rows):
            return None
        return Series(topics["joint_states"], t, np.array([np.asarray(getattr(r[2], attr), float) for r in rows]),
                      names=names)

    joints = field_series("position")
    if joints is None:
        raise BagError(path, "joint_states", f"{topics['joint_states']} gives no position for every joint {names}")
    gaps = _gaps(topics["joint_states"], t)
    wrench = None
    if raw["wrench"]:
        ws = sorted(raw["wrench"], key=lambda r: r[0])
        tw = np.array([(r[0] - t0) * 1e-9 for r in ws])
        values = np.array([_vec(r[2].wrench.force) + _vec(r[2].wrench.torque) for r in ws])
        wrench = Series(topics["wrench"], tw, values, frame=ws[0][2].header.frame_id)
        gaps += _gaps(topics["wrench"], tw)
    targets = []
    for ns, msgtype, msg in sorted(raw["targets"], key=lambda r: r[0]):
        frame = getattr(getattr(msg, "header", None), "frame_id", "")
        if msgtype.endswith("PointStamped"):
            shown = ShownTarget((ns - t0) * 1e-9, "point", np.array(_vec(msg.point)), frame)
        elif msgtype.endswith("PoseStamped"):
            o = msg.pose.orientation
            shown = ShownTarget((ns - t0) * 1e-9, "pose", np.array(_vec(msg.pose.position) + [o.x, o.y, o.z, o.w]),
                                frame)
        else:
            shown = ShownTarget((ns - t0) * 1e-9, "joints", np.asarray(msg.position, float), frame, list(msg.name))
        targets.append(shown)
    return SessionBag(path, joints, field_series("velocity"), field_series("effort"), wrench, targets, gaps)
