"""The wire format between the host (rehabkit's hardware backend) and a robot-side bridge, over UDP.

One datagram is one message, little-endian::

    header  magic 'RK' (2s) · version (B) · kind (B) · robot id (I) · sequence (I)
            · sent at (d, sender's monotonic clock [s]) · echo (d, the peer's last 'sent at' seen)
            · joint count n (H) · measured-only joint count m (H) · status bits (H) · held ticks (H)
    body    STATE:   q, q̇, τ (3 × n doubles), then the m measured-only joints' positions
            COMMAND: τ (n doubles; m = 0)
            CLOCK:   nothing (n = m = 0): in lock-step, the host's "advance to 'sent at'" and the bridge's
                     "done"; never applied, never dropped by a link impairment relay (it is the clock, not data)
    trailer CRC-32 of everything before it (I)

``held ticks`` (STATE only): the bridge's ticks spent holding the posture for want of a newer
command since the last reset, modulo 2¹⁶ — so the host knows how long each such hold lasted
even when the states sent meanwhile were lost or arrived too late to use.

``echo`` lets the host measure round trips without synchronised clocks. A receiver
accepts a message only if it is well formed (length, magic, version, kind, robot,
joint counts, checksum, finite numbers), newer than the last one accepted (sequence
numbers compared modulo 2³², so duplicates and late arrivals are dropped) and not
stale (sent less than ``max_age`` ago, when both ends share the clock, as over
loopback). Every dropped message is counted by reason; none is ever applied.
"""

from __future__ import annotations

import math
import struct
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

MAGIC = b"RK"
VERSION = 4  # 2: measured-only joints (e.g. a passive pronation joint's encoder) in STATE; 3: held ticks; 4: CLOCK
STATE, COMMAND, CLOCK = 1, 2, 3
HEADER = struct.Struct("<2sBBIIddHHHH")
CRC = struct.Struct("<I")

# status bits (bridge → host)
ENABLED, HOLDING, ESTOPPED, WATCHDOG = 1, 2, 4, 8
# the bridge bridges a gap in the commands by holding the posture itself (still enabled: the next command resumes)
STALE = 16
# the bridge's own limit check tripped (a joint beyond its range or speed by more than the bridge's margin)
LIMIT = 32
# command flags, sent in the status field (host → bridge)
CMD_ESTOP, CMD_HOLD, CMD_RESET = 1, 2, 4  # RESET: the values are joint positions to (re)start at


@dataclass
class Message:
    """A decoded message."""

    kind: int
    robot: int
    seq: int
    sent_at: float
    echo: float
    status: int
    held: int  # STATE: ticks held for want of a command since the reset, mod 2**16
    values: np.ndarray  # STATE: (3, n) rows q, qd, tau; COMMAND: (n,) torques
    measured: np.ndarray = field(default_factory=lambda: np.zeros(0))  # STATE: measured-only joint positions

    @property
    def n(self) -> int:
        return self.values.shape[-1]


def encode(kind: int, robot: int, seq: int, values: np.ndarray, sent_at: float | None = None, echo: float = 0.0,
           status: int = 0, held: int = 0, measured: np.ndarray | None = None) -> bytes:
    """One datagram (``values``: (3, n) for STATE, (n,) for COMMAND; ``measured``: STATE only)."""
    values = np.ascontiguousarray(values, dtype="<f8")
    extra = np.ascontiguousarray(np.zeros(0) if measured is None else measured, dtype="<f8").ravel()
    n = values.shape[-1]
    if kind == CLOCK:
        values = values.reshape(0)
    elif kind == STATE and values.shape != (3, n) or kind == COMMAND and values.shape != (n,):
        raise ValueError(f"kind {kind} takes {'(3, n)' if kind == STATE else '(n,)'} values, got {values.shape}")
    if kind == COMMAND and len(extra):
        raise ValueError("commands carry no measured-only joints")
    head = HEADER.pack(MAGIC, VERSION, kind, robot, seq & 0xFFFFFFFF,
                       time.monotonic() if sent_at is None else sent_at, echo, n, len(extra), status, held & 0xFFFF)
    body = head + values.tobytes() + extra.tobytes()
    return body + CRC.pack(zlib.crc32(body))


def clock_time(data: bytes, robot: int) -> float | None:
    """The time a well-formed CLOCK datagram of ``robot`` carries, else None (any other datagram)."""
    if len(data) != HEADER.size + CRC.size or CRC.unpack_from(data, HEADER.size)[0] != zlib.crc32(data[: HEADER.size]):
        return None
    magic, version, kind, rid, _seq, sent_at, *_ = HEADER.unpack_from(data)
    ok = magic == MAGIC and version == VERSION and kind == CLOCK and rid == robot and math.isfinite(sent_at)
    return sent_at if ok else None


def newer(seq: int, last: int) -> bool:
    """Serial-number order (RFC 1982) on 32 bits: ``seq`` comes after ``last``."""
    diff = (seq - last) & 0xFFFFFFFF
    return 0 < diff < 0x80000000


@dataclass
class Receiver:
    """Validates incoming datagrams of one kind from one robot; counts what it drops and why."""

    kind: int
    robot: int
    joints: int
    measured: int = 0  # measured-only joints each STATE carries
    max_age: float | None = None  # seconds; None: senders do not share our clock
    last_seq: int | None = None
    restart: int = 0  # status bits that open a new session: its sequence numbers start over
    accepted: int = 0
    dropped: Counter = field(default_factory=Counter)

    def accept(self, data: bytes, now: float | None = None) -> Message | None:
        """The message if it may be applied, else ``None`` (and the reason counted)."""
        msg, reason = self._parse(data)
        if msg is None:
            self.dropped[reason] += 1
            return None
        if self.last_seq is not None and not msg.status & self.restart and not newer(msg.seq, self.last_seq):
            self.dropped["duplicate" if msg.seq == self.last_seq else "out-of-order"] += 1
            return None
        if self.max_age is not None:
            age = (time.monotonic() if now is None else now) - msg.sent_at
            if age > self.max_age:
                self.dropped["stale"] += 1
                return None
        self.last_seq = msg.seq
        self.accepted += 1
        return msg

    def _parse(self, data: bytes) -> tuple[Message | None, str]:
        per_joint = 3 if self.kind == STATE else 1
        count = per_joint * self.joints + self.measured
        expected = HEADER.size + 8 * count + CRC.size
        if len(data) != expected:
            return None, "length"
        if CRC.unpack_from(data, expected - CRC.size)[0] != zlib.crc32(data[: expected - CRC.size]):
            return None, "checksum"
        magic, version, kind, robot, seq, sent_at, echo, n, m, status, held = HEADER.unpack_from(data)
        if magic != MAGIC:
            return None, "magic"
        if version != VERSION:
            return None, "version"
        if kind != self.kind:
            return None, "kind"
        if robot != self.robot:
            return None, "robot"
        if n != self.joints or m != self.measured:
            return None, "joints"
        values = np.frombuffer(data, dtype="<f8", count=count, offset=HEADER.size)
        if not (np.all(np.isfinite(values)) and math.isfinite(sent_at) and math.isfinite(echo)):
            return None, "non-finite"
        head = values[: per_joint * n]
        head = head.reshape(3, n) if self.kind == STATE else head
        return Message(kind, robot, seq, sent_at, echo, status, held, head.copy(), values[per_joint * n:].copy()), ""
