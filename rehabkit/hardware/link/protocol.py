"""The wire format between the host (rehabkit's hardware backend) and a robot-side bridge, over UDP.

One datagram is one message, little-endian::

    header  magic 'RK' (2s) · version (B) · kind (B) · robot id (I) · sequence (I)
            · sent at (d, sender's monotonic clock [s]) · echo (d, the peer's last 'sent at' seen)
            · joint count n (H) · measured-only joint count m (H) · status bits (H) · held ticks (H)
            · instrument values k (H) · session id (I; 0: none)
    body    STATE:   q, q̇, τ (3 × n doubles), then the m measured-only joints' positions, then the k values of
                     the robot's instruments (force-torque sensors, accelerometers: 3 each, in the order the
                     run's sensors declare them, read by the plant at the tick that state closes)
            COMMAND: τ (n doubles; m = 0)
            CLOCK:   nothing (n = m = 0): in lock-step, the host's "advance to 'sent at'" and the bridge's
                     "done, the link's time is now 'sent at'"; never applied, never dropped by a link impairment
                     relay (it is the clock, not data)
            CLEAR:   the name of the person clearing a latched e-stop, UTF-8 (k = its length in bytes)
            (the handshake's kinds: :mod:`rehabkit.hardware.security.handshake`)
    trailer session id 0 (a link without a key, loopback only): CRC-32 of everything before it (I);
            else the body is encrypted and header and body authenticated in the session
            (:class:`~rehabkit.hardware.security.session.Session`: ChaCha20-Poly1305, a 16-byte tag)

Each end opens a datagram once (its link's :meth:`open`: the checksum, or the session's tag and anti-replay
window) and reads what it says from the opened bytes (header and body): :func:`link_tick`, :meth:`Receiver.take`.

In lock-step the clock usually rides on the data: a COMMAND with the ``TICK`` status bit is the command and
then the host's CLOCK at its 'sent at'; a STATE with ``TICK`` is the state and then the bridge's CLOCK at its
'sent at' (the end of the tick). One datagram each way per tick instead of two: each costs a process wake-up
on both ends. A bare CLOCK goes when there is no data to carry it (or a relay drops the data).

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
VERSION = 9  # 2: measured-only joints (e.g. a passive pronation joint's encoder) in STATE; 3: held ticks; 4: CLOCK;
# 5: instrument values in STATE; 6: the lock-step clock rides on COMMAND and STATE (TICK); 7: authenticated sessions,
# CLEAR with a person's name; 8: the handshake with ephemeral X25519 keys and MAC1, BYE; 9: who may clear (status
# bits), the bridge's BYE to a host whose session was taken over
STATE, COMMAND, CLOCK, CLEAR = 1, 2, 3, 4
HEADER = struct.Struct("<2sBBIIddHHHHHI")
SEQ = struct.Struct("<I")  # the sequence number, at SEQ_AT in the header
SEQ_AT, SESSION_AT = 8, HEADER.size - 4
CRC = struct.Struct("<I")
NAME_BYTES = 64  # a CLEAR's name at most

# status bits (bridge → host)
ENABLED, HOLDING, ESTOPPED, WATCHDOG = 1, 2, 4, 8
# the bridge bridges a gap in the commands by holding the posture itself (still enabled: the next command resumes)
STALE = 16
# the bridge's own limit check tripped (a joint beyond its range or speed by more than the bridge's margin)
LIMIT = 32
# the first session after a latched e-stop was cleared: the host must ramp in
RAMP_IN = 64
# a person cleared a latched e-stop since the last reset (a CLEAR where nothing was latched leaves it unset: "not
# latched")
CLEARED = 128
# a CLEAR came in a session without the right to clear (the bridge takes clears under its clearing key, or at its
# keypad only): the e-stop stays latched
NO_RIGHT = 256
# the bridge declares, in every state, who may clear its latched e-stop over the link: only a session under its
# clearing key (--clear-key: the robot's key does not clear), or no session at all (--clear-with keypad: its keypad
# only); neither bit: any session
CLEAR_BY_KEY, CLEAR_AT_KEYPAD = 512, 1024
# command flags, sent in the status field (host → bridge)
CMD_ESTOP, CMD_HOLD, CMD_RESET = 1, 2, 4  # RESET: the values are joint positions to (re)start at
# (8 was v6's e-stop clear: now a CLEAR datagram, with the person's name)
CMD_BRAKE = 32  # apply the holding brakes (the host's safety stop has turned the torque off)
CMD_LATCH = 16  # latch the e-stop for the sessions to come; this session's stop is the host's (its stop category)
# the host's torques are a compliant reaction (its safety layer yields to the person): a gap in the commands is
# bridged with damping and gravity compensation only, not a stiff hold (a bridge that predates it holds stiffly)
CMD_COMPLIANT = 64
# either way, lock-step only: this datagram also carries the link's clock at its 'sent at' (see the module's doc)
TICK = 0x8000


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
    instruments: np.ndarray = field(default_factory=lambda: np.zeros(0))  # STATE: instrument values

    @property
    def n(self) -> int:
        return self.values.shape[-1]


def pack(kind: int, robot: int, seq: int, values: np.ndarray, sent_at: float | None = None, echo: float = 0.0,
         status: int = 0, held: int = 0, measured: np.ndarray | None = None, instruments: np.ndarray | None = None,
         session: int = 0) -> bytes:
    """A datagram's header and body, before its link seals it (``values``: (3, n) for STATE, (n,) for COMMAND;
    ``measured``, ``instruments``: STATE only)."""
    values = np.ascontiguousarray(values, dtype="<f8")
    extra = np.ascontiguousarray(np.zeros(0) if measured is None else measured, dtype="<f8").ravel()
    readings = np.ascontiguousarray(np.zeros(0) if instruments is None else instruments, dtype="<f8").ravel()
    n = values.shape[-1]
    if kind == CLOCK:
        values = values.reshape(0)
    elif kind == STATE and values.shape != (3, n) or kind == COMMAND and values.shape != (n,):
        raise ValueError(f"kind {kind} takes {'(3, n)' if kind == STATE else '(n,)'} values, got {values.shape}")
    if kind == COMMAND and (len(extra) or len(readings)):
        raise ValueError("commands carry no measured-only joints or instruments")
    head = HEADER.pack(MAGIC, VERSION, kind, robot, seq & 0xFFFFFFFF,
                       time.monotonic() if sent_at is None else sent_at, echo, n, len(extra), status, held & 0xFFFF,
                       len(readings), session)
    return head + values.tobytes() + extra.tobytes() + readings.tobytes()


def pack_bytes(kind: int, robot: int, seq: int, body: bytes, session: int = 0, sent_at: float = 0.0) -> bytes:
    """A datagram of ``kind`` whose body is bytes (a CLEAR's name, the handshake's): k counts them."""
    return HEADER.pack(MAGIC, VERSION, kind, robot, seq & 0xFFFFFFFF, sent_at, 0.0, 0, 0, 0, 0, len(body),
                       session) + body


class PlainLink:
    """A link without a key (loopback only): datagrams carry a CRC-32 against noise, nothing against anyone."""

    id = 0  # its session id

    @staticmethod
    def seal(plain: bytes) -> bytes:
        return plain + CRC.pack(zlib.crc32(plain))

    @staticmethod
    def open(data: bytes) -> tuple[bytes | None, str]:
        """Header and body of an intact datagram, or None and why not."""
        size = len(data) - CRC.size
        if size < HEADER.size:
            return None, "length"
        if CRC.unpack_from(data, size)[0] != zlib.crc32(data[:size]):
            return None, "checksum"
        if SEQ.unpack_from(data, SESSION_AT)[0]:
            return None, "authenticated"  # (sealed in a session this end has no key for)
        return data[:size], ""


PLAIN = PlainLink()


def encode(kind: int, robot: int, seq: int, values: np.ndarray, sent_at: float | None = None, echo: float = 0.0,
           status: int = 0, held: int = 0, measured: np.ndarray | None = None,
           instruments: np.ndarray | None = None, link=PLAIN) -> bytes:
    """One datagram, sealed by ``link`` (a :class:`~rehabkit.hardware.security.session.Session`, or :data:`PLAIN`)."""
    return link.seal(pack(kind, robot, seq, values, sent_at, echo, status, held, measured, instruments, link.id))


def clear_name(plain: bytes, robot: int) -> str | None:
    """The name an opened CLEAR datagram of ``robot`` carries, or None (not one, or no usable name)."""
    if len(plain) <= HEADER.size or len(plain) > HEADER.size + NAME_BYTES:
        return None
    magic, version, kind, rid, *_rest, k, _session = HEADER.unpack_from(plain)
    if (magic, version, kind, rid, k) != (MAGIC, VERSION, CLEAR, robot, len(plain) - HEADER.size):
        return None
    try:
        name = plain[HEADER.size:].decode("utf-8").strip()
    except UnicodeDecodeError:
        return None
    return name if name and name.isprintable() else None


def link_tick(plain: bytes, robot: int) -> tuple[float, bool] | None:
    """The lock-step clock time an opened datagram of ``robot`` carries and whether it is a bare CLOCK (else the
    time rides on a COMMAND or STATE with ``TICK``), or None: no clock in it."""
    if len(plain) < HEADER.size:
        return None
    magic, version, kind, rid, _seq, sent_at, _echo, _n, _m, status, *_ = HEADER.unpack_from(plain)
    if magic != MAGIC or version != VERSION or rid != robot or not math.isfinite(sent_at):
        return None
    if kind == CLOCK:
        return (sent_at, True) if len(plain) == HEADER.size else None
    return (sent_at, False) if status & TICK else None


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
    instruments: int = 0  # instrument values each STATE carries
    max_age: float | None = None  # seconds; None: senders do not share our clock
    last_seq: int | None = None
    restart: int = 0  # status bits that open a new session: its sequence numbers start over (a link without a key)
    link: object = PLAIN  # opens datagrams: checksum, or a session's authentication and anti-replay window
    accepted: int = 0
    dropped: Counter = field(default_factory=Counter)

    def accept(self, data: bytes, now: float | None = None) -> Message | None:
        """The message in a datagram as it came if it may be applied, else ``None`` (and the reason counted)."""
        plain, reason = self.link.open(data)
        if plain is None:
            self.dropped[reason] += 1
            return None
        return self.take(plain, now)

    def take(self, plain: bytes, now: float | None = None) -> Message | None:
        """The message in an opened datagram (header and body) if it may be applied, else ``None`` (counted)."""
        msg, reason = self._parse(plain)
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

    def _parse(self, plain: bytes) -> tuple[Message | None, str]:
        per_joint = 3 if self.kind == STATE else 1
        count = per_joint * self.joints + self.measured + self.instruments
        if len(plain) != HEADER.size + 8 * count:  # another size: say which count differs
            return None, self._counts(plain) if len(plain) >= HEADER.size else "length"
        magic, version, kind, robot, seq, sent_at, echo, n, m, status, held, k, _session = HEADER.unpack_from(plain)
        if magic != MAGIC:
            return None, "magic"
        if version != VERSION:
            return None, "version"
        if kind != self.kind:
            return None, "kind"
        if robot != self.robot:
            return None, "robot"
        if n != self.joints or m != self.measured or k != self.instruments:
            return None, self._counts(plain)
        values = np.frombuffer(plain, dtype="<f8", count=count, offset=HEADER.size)
        if not (np.all(np.isfinite(values)) and math.isfinite(sent_at) and math.isfinite(echo)):
            return None, "non-finite"
        head = values[: per_joint * n]
        head = head.reshape(3, n) if self.kind == STATE else head
        rest = values[per_joint * n:]
        return Message(kind, robot, seq, sent_at, echo, status, held, head.copy(), rest[:m].copy(), rest[m:].copy()), ""

    def _counts(self, plain: bytes) -> str:
        """Why an intact datagram does not fit: another protocol version, kind, joint count or instrument count."""
        fields = HEADER.unpack_from(plain)
        if fields[0] != MAGIC or fields[1] != VERSION:
            return "version"
        if fields[2] != self.kind:
            return "kind"
        n, m, k = fields[7], fields[8], fields[11]
        return "instruments" if (n, m) == (self.joints, self.measured) and k != self.instruments else "joints"
