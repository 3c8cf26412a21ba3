"""A session recorded on a robot, read from its ROS bag: the joints, the person's wrench, the targets as shown.

The bag is read with ``rosbags`` (ROS 2 bags in MCAP or SQLite, a folder with ``metadata.yaml`` or a bare ``.mcap``
file, and ROS 1 bags). Each role is a topic (``/joint_states``, ``/wrench``, ``/targets``,
``/reference/joint_states`` unless renamed; the targets also on ``<targets>/pose`` and ``<targets>/joint_states``, as
rehabkit's bags have them); its times are the messages' header stamps (the log time where a stamp is zero), from the
first joint state on. A stretch without messages much longer than the topic's usual period is a :class:`Gap`: said,
and bridged by interpolation. What the messages hold is checked as it is read (:mod:`rehabkit.bags.bag_content`):
refused, or said, at the message.

A role's topic missing from the bag is refused, but for two left at their default topic: the reference (the joints'
reference, as rehabkit's bags have it: done without) and the person's wrench where the bag has no other
``WrenchStamped`` topic to take for it (outside ``/sensors/``, where rehabkit's bags keep a force-torque sensor's
readings): the session is replayed without a recorded person, said.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rehabkit.bags.bag_content import BagError, Remark, Where, not_finite, refuse_rows

TOPICS = {"joint_states": "/joint_states", "wrench": "/wrench", "targets": "/targets",
          "reference": "/reference/joint_states"}
TYPES = {"joint_states": ("sensor_msgs/msg/JointState",),
         "wrench": ("geometry_msgs/msg/WrenchStamped",),
         "targets": ("geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/JointState"),
         "reference": ("sensor_msgs/msg/JointState",)}
FIX = {"joint_states": "name the joint states' topic: --topics joint_states=TOPIC",
       "wrench": "name the person's wrench topic: --topics wrench=TOPIC; or --topics wrench= to replay without it, "
                 "the scenario's own patient (if any) in the robot",
       "targets": "name the targets' topic: --topics targets=TOPIC; or --topics targets= to replay without them, "
                  "on the scenario's own task",
       "reference": "name the joints' reference topic: --topics reference=TOPIC; or --topics reference= to tell the "
                    "plans apart by the measured joints"}
WRENCH = "geometry_msgs/msg/WrenchStamped"
SENSORS = "/sensors/"  # rehabkit's bags: each sensor's readings (a force-torque sensor's: WrenchStamped), no person's
# the targets' topic's companions (rehabkit's bags: a topic per kind of target), each with its type
COMPANIONS = {"/pose": "geometry_msgs/msg/PoseStamped", "/joint_states": "sensor_msgs/msg/JointState"}
GAP_PERIODS = 5.0  # a stretch this many usual periods long without a message is a gap
GAP_MIN_S = 0.05  # ... and at least this long (a 1 kHz topic missing 6 ms is jitter, not a gap)
# the messages read from bags while :func:`reading_once` holds: (bag, connections read) → (connection, log time,
# message) in the order read. A replay reads its bag, then the recorded-wrench patient it builds reads the same joint
# states and wrench again; deserialising a 1 kHz session's messages is most of the reading (an 8-s session: 16,000
# messages, ~0.3 s of a ~1.9 s replay), so read twice it was a third of the replay
_READ: ContextVar[dict | None] = ContextVar("rehabkit_bags_read", default=None)


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
    where: Where | None = None  # its message


@dataclass
class SessionBag:
    """What the bag holds for a replay; ``joints`` names, ``position``/``velocity``/``effort`` their samples (the
    last two None where the messages leave them empty, or hold a number that is not finite: a ``remark``);
    ``t0_ns`` the session's start (the first joint state's stamp, Unix epoch); ``reference`` the joints' reference
    where the bag has one (rehabkit's bags: ``/reference/joint_states``)."""

    path: Path
    joints: Series
    velocity: Series | None
    effort: Series | None
    wrench: Series | None
    targets: list[ShownTarget]
    gaps: list[Gap]
    t0_ns: int = 0
    remarks: list[Remark] = field(default_factory=list)
    reference: Series | None = None  # the joints' reference (positions; its ``names`` those of the joint states')
    reference_velocity: Series | None = None  # ... its velocities, where every message has them, finite
    topics: dict[str, str] = field(default_factory=dict)  # the topic read for each role ('' for none)

    @property
    def duration_s(self) -> float:
        """How long the session lasted: to its last joint state, and that sample's period."""
        return float(self.joints.t[-1] + np.median(np.diff(self.joints.t)))


def parse_topics(items: list[str]) -> dict[str, str]:
    """The roles named by ``ROLE=TOPIC`` items (each may hold several, comma-separated); ``ROLE=`` for none (the
    wrench or the targets: the replay keeps the scenario's own person or task; the reference: the plans told apart
    by the measured joints). Roles not named keep their default topic (:data:`TOPICS`, where :func:`read_session`
    merges them), a named one's topic must be in the bag."""
    topics: dict[str, str] = {}
    for item in items:
        for pair in filter(None, item.split(",")):
            role, sep, topic = pair.partition("=")
            if not sep or role.strip() not in TOPICS or (role.strip() == "joint_states" and not topic.strip()):
                raise BagError("--topics", "", f"'{pair}': give ROLE=TOPIC with ROLE one of {', '.join(TOPICS)} "
                                                f"(e.g. --topics wrench=/cuff/wrench; wrench=, targets= or "
                                                f"reference= for none)")
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
    """The joints, wrench, targets and reference of the bag at ``path`` (``topics``: the roles named, the others at
    :data:`TOPICS`; only the ``roles`` asked for are read, the joint states always). The targets are those of the
    targets' topic and of its companions (:data:`COMPANIONS`: ``<targets>/pose``, ``<targets>/joint_states``), where
    the bag has them. A reference or a wrench not named and missing is done without (:func:`_wanted`); the session's
    ``topics`` say which were read.

    Raises:
        BagError: the bag can't be read, a topic is missing or of another type, joint states are empty, or a message
            holds what can't be replayed (at the message).
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    named = set(topics or {})
    path, topics = Path(path), {**TOPICS, **(topics or {})}
    topics = {role: topic for role, topic in topics.items() if (role in roles or role == "joint_states") and topic}
    if not path.exists():
        raise BagError(path, "", "no such bag (a rosbag2 folder with metadata.yaml, an .mcap file, or a ROS 1 .bag)")
    raw: dict[str, list] = {role: [] for role in TOPICS}
    remarks: list[Remark] = []
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            have = {c.topic: c.msgtype for c in reader.connections}
            wanted, problems = _wanted(topics, have, named, path, remarks)
            if problems:
                raise BagError(path, *problems[0], more=problems[1:])
            conns = [c for c in reader.connections if c.topic in wanted]
            for conn, log_ns, msg in _messages(reader, path, conns):
                raw[wanted[conn.topic]].append((_stamp_ns(msg, log_ns), conn.topic, conn.msgtype, msg))
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors: a damaged or unknown file
        raise BagError(path, "", f"can't be read as a ROS bag: {exc}") from exc
    roles_read = set(wanted.values())
    return _session(path, topics, raw, remarks, {role: topics[role] if role in roles_read else "" for role in TOPICS})


@contextmanager
def reading_once() -> Iterator[None]:
    """Within it, a bag's messages are deserialised once: a later :func:`read_session` of the same bag, unchanged on
    disk, for the same connections or some of them takes them from the first read (a connection's messages in the
    order read: the order rosbags' readers give them alone or among others — time order, ties in the file's order).
    Outside it (and once it ends) nothing is kept: a long session's messages are not held for the process's life."""
    if _READ.get() is not None:  # (nested: the outer one keeps them)
        yield
        return
    token = _READ.set({})
    try:
        yield
    finally:
        _READ.reset(token)


def _identity(path: Path) -> tuple:
    """The bag as it is on disk: its path and each of its files' name, size and modification time."""
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return str(path.resolve()), tuple((str(p), st.st_size, st.st_mtime_ns) for p in files for st in [p.stat()])


def _messages(reader, path: Path, conns: list) -> Iterator[tuple]:
    """``conns``' messages, deserialised, in the order the reader gives them: (connection, log time [ns], message);
    within :func:`reading_once`, those of an earlier read of the bag that had them all."""
    kept = _READ.get()
    if kept is None:
        for conn, log_ns, data in reader.messages(connections=conns):
            yield conn, log_ns, reader.deserialize(data, conn.msgtype)
        return
    bag = _identity(path)
    mine = {(c.id, c.topic, c.msgtype): c for c in conns}
    for (other, read), messages in kept.items():
        if other == bag and mine.keys() <= read:
            yield from ((mine[key], log_ns, msg) for key, log_ns, msg in messages if key in mine)
            return
    messages = [((conn.id, conn.topic, conn.msgtype), log_ns, reader.deserialize(data, conn.msgtype))
                for conn, log_ns, data in reader.messages(connections=conns)]
    kept[bag, frozenset(mine)] = messages
    yield from ((mine[key], log_ns, msg) for key, log_ns, msg in messages)


def _wanted(topics: dict[str, str], have: dict[str, str], named: set[str] = frozenset(), path: Path | str = "",
            remarks: list[Remark] | None = None) -> tuple[dict[str, str], list[tuple[str, str]]]:
    """The topics to read (topic → role), and what is missing or of another type (role, what). Not named
    (``named``) and missing: the reference is done without, and so is the person's wrench where the bag has no
    other ``WrenchStamped`` topic to take for theirs (outside :data:`SENSORS`): said in ``remarks``."""
    listing = ", ".join(f"{t} ({m})" for t, m in sorted(have.items()))
    wanted, problems = {}, []
    for role, topic in topics.items():
        if role in named or topic in have:
            pass
        elif role == "reference":
            continue
        elif role == "wrench" and not [t for t, m in have.items() if m == WRENCH and not t.startswith(SENSORS)]:
            sensed = [t for t, m in have.items() if m == WRENCH]
            also = f" ({', '.join(sensed)}: a sensor's, not taken)" if sensed else ""
            if remarks is not None:
                remarks.append(Remark(str(path), "--topics wrench", f"no topic {topic}, nor another {WRENCH}{also}: "
                                      "no person's wrench recorded; replayed without one (the scenario's own "
                                      "patient, if it has one; name their wrench's topic: --topics wrench=TOPIC)"))
            continue
        companions = {topic + tail: msgtype for tail, msgtype in COMPANIONS.items()} if role == "targets" else {}
        for name, msgtype in companions.items():
            if name in have and have[name] != msgtype:
                problems.append((role, f"{name} is {have[name]}; the targets' {name.removeprefix(topic)} must be "
                                       f"{msgtype} (name the targets' topic otherwise: --topics targets=TOPIC)"))
            elif name in have:
                wanted[name] = role
        if topic not in have and any(name in have for name in companions):
            continue
        if topic not in have:
            also = f" (nor {', '.join(companions)})" if companions else ""
            problems.append((role, f"no topic {topic}{also}; the bag has {listing} ({FIX[role]})"))
        elif have[topic] not in TYPES[role]:
            problems.append((role, f"{topic} is {have[topic]}; {role} must be {' or '.join(TYPES[role])}"))
        else:
            wanted[topic] = role
    return wanted, problems


class _Wheres(Sequence):
    """Each of ``rows``' messages as a :class:`Where` (``wheres[i]``), made for the one said only: a 1 kHz session has
    tens of thousands, and almost always none is."""

    def __init__(self, rows: list, where):
        self.rows, self.where = rows, where

    def __getitem__(self, i: int) -> Where:
        return self.where(self.rows[i])

    def __len__(self) -> int:
        return len(self.rows)


def _series_rows(path: Path, topic: str, rows: list, t: np.ndarray, names: list[str], wheres: _Wheres,
                 remarks: list[Remark]) -> tuple[Series, Series | None, Series | None]:
    """The joint states' position, velocity and effort series; a position that is not finite refused, a velocity or
    effort said and left out."""
    position = np.array([np.asarray(r[3].position, float) for r in rows])
    refuse_rows(path, "joint_states", position, wheres, [f"position[{n}]" for n in names],
                [f"position of '{n}'" for n in names])
    out = []
    for attr, instead in (("velocity", "the replay's are the positions' rate of change"),
                          ("effort", "the session's torques are not known")):
        if any(len(getattr(r[3], attr)) != len(names) for r in rows):
            out.append(None)
            continue
        values = np.array([np.asarray(getattr(r[3], attr), float) for r in rows])
        bad = ~np.isfinite(values)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            said = f"{attr} of '{names[col]}' is {not_finite(values[row, col])}"
            remarks.append(Remark(str(path), wheres[row], f"{said} ({int(bad.sum())} value(s) not finite): {attr} "
                                                          f"not used ({instead})"))
            out.append(None)
            continue
        out.append(Series(topic, t, values, names=names))
    return Series(topic, t, position, names=names), out[0], out[1]


def _session(path: Path, topics: dict[str, str], raw: dict[str, list], remarks: list[Remark],
             read: dict[str, str]) -> SessionBag:
    js = sorted(raw["joint_states"], key=lambda r: r[0])
    if len(js) < 2:
        raise BagError(path, "joint_states", f"{topics['joint_states']} has {len(js)} message(s); a replay needs the "
                                              "session's joint states")
    names = list(js[0][3].name)
    t0 = js[0][0]

    def where(r) -> Where:
        return Where(r[1], (r[0] - t0) * 1e-9, r[0])

    t = np.array([(r[0] - t0) * 1e-9 for r in js])
    keep = np.concatenate([[True], np.diff(t) > 0])  # a repeated stamp: the first message counts
    rows = [r for r, k in zip(js, keep) if k]
    t = t[keep]
    changed = [r for r in rows if list(r[3].name) != names]
    if changed:
        raise BagError(path, "joint_states", f"names joints {list(changed[0][3].name)}, the first message {names}: "
                                              "a replay needs one joint order", where=where(changed[0]), field="name")
    short = [r for r in rows if len(r[3].position) != len(names)]
    if short:
        raise BagError(path, "joint_states", f"gives {len(short[0][3].position)} positions for the joints {names}: "
                                              "a replay needs every joint's position in every message",
                       where=where(short[0]), field="position")
    joints, velocity, effort = _series_rows(path, topics["joint_states"], rows, t, names, _Wheres(rows, where),
                                            remarks)
    gaps = _gaps(topics["joint_states"], t)
    wrench = None
    if raw["wrench"]:
        ws = sorted(raw["wrench"], key=lambda r: r[0])
        values = np.array([_vec(r[3].wrench.force) + _vec(r[3].wrench.torque) for r in ws])
        refuse_rows(path, "wrench", values, _Wheres(ws, where),
                    [f"wrench.{a}.{x}" for a in ("force", "torque") for x in "xyz"])
        frame = ws[0][3].header.frame_id
        other = next((r for r in ws if r[3].header.frame_id != frame), None)
        if other is not None:
            raise BagError(path, "wrench", f"is in frame '{other[3].header.frame_id}', the first message in '{frame}': "
                                           "the recorded wrench is replayed in one frame (name it with the "
                                           "recorded-wrench patient's frame, or record one frame)",
                           where=where(other), field="header.frame_id")
        tw = np.array([(r[0] - t0) * 1e-9 for r in ws])
        wrench = Series(topics["wrench"], tw, values, frame=frame)
        gaps += _gaps(topics["wrench"], tw)
    targets = [_shown(path, r, where(r), t0) for r in sorted(raw["targets"], key=lambda r: r[0])]
    reference, reference_velocity = _reference(path, read["reference"], raw["reference"], names, t0, remarks)
    if reference is None:
        read = {**read, "reference": ""}
    return SessionBag(path, joints, velocity, effort, wrench, targets, gaps, t0, remarks, reference,
                      reference_velocity, read)


def _reference(path: Path, topic: str, raw: list, names: list[str], t0: int, remarks: list[Remark]
               ) -> tuple[Series | None, Series | None]:
    """The joints' reference (positions, and velocities where every message has them), of the joint states' joints
    it names (in their order); not used where it names none of them, or a position is not finite (said)."""
    rows = sorted(raw, key=lambda r: r[0])
    if len(rows) < 2:
        return None, None
    t = np.array([(r[0] - t0) * 1e-9 for r in rows])
    keep = np.concatenate([[True], np.diff(t) > 0])
    rows, t = [r for r, k in zip(rows, keep) if k], t[keep]
    first = list(rows[0][3].name)
    common = [n for n in names if n in first]
    unlike = next((r for r in rows if list(r[3].name) != first or len(r[3].position) != len(first)), None)
    why = ("names none of the joint states' joints" if not common else
           "changes the joints it names, or gives a position per joint in some messages only" if unlike else "")
    cols = [first.index(n) for n in common]
    position = np.array([np.asarray(r[3].position, float)[cols] for r in rows]) if not why else None
    if position is not None and not np.isfinite(position).all():
        why = "holds a position that is not finite"
    if why:
        remarks.append(Remark(str(path), topic, f"the joints' reference {why}: not used (the plans told apart by the "
                                                "measured joints)"))
        return None, None
    velocity = None
    if all(len(r[3].velocity) == len(first) for r in rows):
        v = np.array([np.asarray(r[3].velocity, float)[cols] for r in rows])
        velocity = Series(topic, t, v, names=common) if np.isfinite(v).all() else None
    return Series(topic, t, position, names=common), velocity


def _shown(path: Path, r: tuple, at: Where, t0: int) -> ShownTarget:
    """A target message as shown: refused where a number is not finite, or a pose's orientation is no rotation."""
    ns, _, msgtype, msg = r
    frame = getattr(getattr(msg, "header", None), "frame_id", "")
    if msgtype.endswith("PointStamped"):
        kind, values, fields = "point", np.array(_vec(msg.point)), [f"point.{x}" for x in "xyz"]
    elif msgtype.endswith("PoseStamped"):
        o = msg.pose.orientation
        kind, values = "pose", np.array(_vec(msg.pose.position) + [o.x, o.y, o.z, o.w])
        fields = [f"pose.position.{x}" for x in "xyz"] + [f"pose.orientation.{x}" for x in "xyzw"]
    else:
        kind, values = "joints", np.array(msg.position, float)  # (a copy: the message may be read again)
        fields = [f"position[{n}]" for n in msg.name]
        if len(values) != len(msg.name):
            raise BagError(path, "targets", f"gives {len(values)} positions for the joints {list(msg.name)}: a "
                                            "posture target needs one per joint", where=at, field="position")
    words = [f"position of '{n}'" for n in msg.name] if kind == "joints" else None
    refuse_rows(path, "targets", values[None], [at], fields, words)
    if kind == "pose" and not 0.5 < np.linalg.norm(values[3:]) < 1.5:
        raise BagError(path, "targets", f"pose.orientation {values[3:].tolist()} is no rotation (a unit quaternion "
                                        "x, y, z, w): give the hand's orientation, or send a PointStamped for a "
                                        "position alone", where=at, field="pose.orientation")
    return ShownTarget((ns - t0) * 1e-9, kind, values, frame, list(getattr(msg, "name", [])), at)
