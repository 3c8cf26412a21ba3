"""A ROS 2 bag written as a run goes: an MCAP file (profile ``ros2``, CDR messages, the schemas as rosbag2 stores
them: :mod:`rehabkit.ros.msgdefs`), whose messages reach the file in whole chunks at each :meth:`BagWriter.flush`.

Why not ``mcap_ros2``'s writer: it has no flush (a chunk reaches the file only when it is full, 1 MiB: minutes of a
slow topic), so a killed run lost everything since its last full chunk. Here the ``mcap`` library's own writer
(its public ``flush`` closes the chunk under way) is given the messages encoded by ``rosbags``' type store (ROS 2
Humble's definitions, the same bytes as ``mcap_ros2`` writes, at a third of its cost a message).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rehabkit.core.version import __version__
from rehabkit.ros.msgdefs import datatype, msgdef

CHUNK_BYTES = 256 * 1024  # (a full chunk is compressed in the call that fills it: ~1 ms at this size, not ~4 ms)
_NUMPY = {"float64": np.float64, "float32": np.float32, "uint8": np.uint8, "int8": np.int8, "uint16": np.uint16,
          "int16": np.int16, "uint32": np.uint32, "int32": np.int32, "uint64": np.uint64, "int64": np.int64,
          "bool": np.bool_, "byte": np.uint8, "char": np.uint8}


def _store():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _builder(store, rostype: str, made: dict[str, Callable]) -> Callable[[dict], Any]:
    """``message dict → rosbags message`` for one type: each field as the type store's class takes it (numeric arrays
    as numpy arrays, nested messages built the same way); a field the dict leaves out takes ROS's default."""
    if rostype in made:
        return made[rostype]
    from rosbags.interfaces import Nodetype

    cls, (_, fields) = store.types[rostype], store.fielddefs[rostype]
    convert: list[tuple[str, Callable[[Any], Any], Callable[[], Any]]] = []
    for name, (node, detail) in fields:
        if node == Nodetype.BASE:
            kind = detail[0]
            if kind == "string":
                convert.append((name, str, str))
            elif kind in ("float32", "float64"):
                convert.append((name, float, float))
            else:
                convert.append((name, int, int))
        elif node == Nodetype.NAME:
            sub = _builder(store, detail, made)
            convert.append((name, sub, lambda sub=sub: sub({})))
        else:  # an array or a sequence
            (inner, inner_detail), _ = detail
            if inner == Nodetype.BASE and inner_detail[0] == "string":
                convert.append((name, list, list))
            elif inner == Nodetype.BASE:
                dt = _NUMPY[inner_detail[0]]

                def numeric(v, dt=dt):
                    return np.frombuffer(v, dt) if isinstance(v, bytes | bytearray) else np.asarray(v, dt)
                convert.append((name, numeric, lambda dt=dt: np.zeros(0, dt)))
            else:
                sub = _builder(store, inner_detail, made)
                convert.append((name, lambda v, sub=sub: [sub(x) for x in v], list))

    def build(value: dict) -> Any:
        return cls(**{name: (conv(value[name]) if name in value else default()) for name, conv, default in convert})
    made[rostype] = build
    return build


class BagWriter:
    """A ROS 2 bag (MCAP) at ``path``: :meth:`put` a message (its fields as a dict, the type as ``pkg/Type``),
    :meth:`flush` to have every message put so far in the file (a killed process's bag reads up to there),
    :meth:`finish` to write its index and close it. ``counts`` and ``types``: the messages put, by topic."""

    def __init__(self, path: Path, chunk_bytes: int = CHUNK_BYTES):
        from mcap.writer import CompressionType, Writer

        self.file = open(path, "wb")  # noqa: SIM115 (closed in finish, or by the owner's discard)
        self.writer = Writer(self.file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD)
        self.writer.start(profile="ros2", library=f"rehabkit {__version__}")
        self.store = _store()
        self._builders: dict[str, Callable] = {}
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str, Callable]] = {}  # topic → channel id, ROS type, builder
        self.counts: Counter = Counter()
        self.types: dict[str, str] = {}

    def _channel(self, topic: str, msg_type: str) -> tuple[int, str, Callable]:
        rostype = datatype(msg_type)
        if msg_type not in self._schemas:
            self._schemas[msg_type] = self.writer.register_schema(rostype, "ros2msg", msgdef(msg_type).encode())
        ch = (self.writer.register_channel(topic, "cdr", self._schemas[msg_type]), rostype,
              _builder(self.store, rostype, self._builders))
        self._channels[topic] = ch
        self.types[topic] = rostype
        return ch

    def put(self, topic: str, msg_type: str, message: dict, ns: int) -> None:
        """``message`` on ``topic``, logged and published at ``ns`` (Unix epoch, nanoseconds)."""
        channel, rostype, build = self._channels.get(topic) or self._channel(topic, msg_type)
        data = self.store.serialize_cdr(build(message), rostype)
        self.writer.add_message(channel, log_time=ns, publish_time=ns, sequence=self.counts[topic], data=data)
        self.counts[topic] += 1

    def flush(self) -> None:
        """The chunk under way closed and written out (to the OS: a killed process's messages are in the file; not
        fsynced, which a power cut would need — the safety log is)."""
        self.writer.flush()

    def finish(self) -> None:
        """The bag's summary and index written, the file closed."""
        self.writer.finish()
        self.file.close()
