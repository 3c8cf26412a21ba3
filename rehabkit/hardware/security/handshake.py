"""The handshake proving both ends hold the robot's key, and the bridge's gate that keeps the session it opens.

Each message is a datagram of its own kind, its body bytes (``K`` the robot's key, ``id`` its key id)::

    host   → bridge   HELLO      id · Nh                           a fresh 16-byte nonce of the host's
    bridge → host     CHALLENGE  id · Nh · Nb · HMAC(K, "bridge" · robot · id · Nh · Nb)
    host   → bridge   PROOF      id · Nh · Nb · HMAC(K, "host" · robot · id · Nh · Nb)
    bridge → host     WELCOME    (empty, sealed in the new session: it holds the same keys)
    bridge → host     REFUSED    why · the bridge's key id      (a key the bridge does not hold, or none at all)

Both proofs bind both nonces, so neither can be replayed into another handshake; the bridge keeps the nonces it
issued for a few seconds, each for one proof only. The session's keys and id:
:func:`~rehabkit.hardware.security.session.session_for`. The bridge answers datagrams outside a session (challenges,
refusals) at most ``ANSWERS_PER_S`` a second, never with more bytes than came.
"""

from __future__ import annotations

import hmac
import secrets
import time
from collections import OrderedDict

from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.protocol import HEADER, MAGIC, PLAIN, SEQ, SESSION_AT, VERSION, pack_bytes
from rehabkit.hardware.security.keys import LinkKey
from rehabkit.hardware.security.session import KEY_ID, MAC, NONCE, Session, proof, session_for

HELLO, CHALLENGE, PROOF, WELCOME, REFUSED = 5, 6, 7, 8, 9
HANDSHAKE = frozenset((HELLO, CHALLENGE, PROOF, WELCOME, REFUSED))
PENDING = 16  # nonces issued and not yet proven, kept at most (a flood of HELLOs only rotates them)
PENDING_S = 5.0  # how long an issued nonce may be proven
ANSWERS_PER_S = 20.0  # answers (challenges, refusals) to datagrams not in a session, at most
# REFUSED's reasons
NO_KEY, OTHER_KEY, KEY_NEEDED = 1, 2, 3
REFUSALS = {NO_KEY: "has no key (it was started without --key)", OTHER_KEY: "holds another key",
            KEY_NEEDED: "needs a key (it was started with --key)"}
_BODY = {HELLO: KEY_ID + NONCE, CHALLENGE: KEY_ID + 2 * NONCE + MAC, PROOF: KEY_ID + 2 * NONCE + MAC,
         REFUSED: 1 + KEY_ID}

def handshake_body(plain: bytes, robot: int) -> tuple[int, bytes] | None:
    """Kind and body of an opened handshake datagram for ``robot`` of the right size, else None."""
    if len(plain) < HEADER.size:
        return None
    magic, version, kind, rid, *_rest, k, _sid = HEADER.unpack_from(plain)
    body = plain[HEADER.size:]
    if (magic, version, rid) != (MAGIC, VERSION, robot) or kind not in _BODY or not len(body) == _BODY[kind] == k:
        return None
    return kind, body


def peek_kind(data: bytes) -> int:
    """A datagram's kind as its header says (before anything is checked: which end of the protocol reads it)."""
    return data[3] if len(data) >= HEADER.size else 0


class BridgeGate:
    """The bridge's end: answers handshakes, keeps the newest proven session (a new one replaces it, as a new host's
    reset took the link over before keys), opens datagrams in it, and counts what it refuses by reason."""

    def __init__(self, key: LinkKey | None, robot: int):
        self.key, self.robot = key, robot
        self.session: Session | None = None
        self.peer: tuple | None = None  # the address that proved the session
        self._pending: OrderedDict[bytes, tuple[bytes, float]] = OrderedDict()  # Nb → (Nh, issued at)
        self.seq = 0
        self._budget, self._refilled = ANSWERS_PER_S, 0.0

    def reply(self, data: bytes, addr: tuple, now: float | None = None) -> tuple[bytes | None, str]:
        """A handshake datagram from ``addr`` (after :func:`peek_kind`): the reply to send back (or None) and, if it
        was refused, why (counted by the caller); a proven PROOF opens a new session (:attr:`session`) with it."""
        now = time.monotonic() if now is None else now
        plain, why = PLAIN.open(data)
        got = handshake_body(plain, self.robot) if plain is not None else None
        if got is None:
            return None, why or "handshake"
        kind, body = got
        if kind not in (HELLO, PROOF):
            return None, "handshake"
        key_id = body[:KEY_ID]
        if self.key is None:
            return self._refuse(NO_KEY) if self._spend(now) else None, "no-key"
        if key_id != bytes.fromhex(self.key.id):
            return self._refuse(OTHER_KEY) if self._spend(now) else None, "other-key"
        nh = body[KEY_ID:KEY_ID + NONCE]
        if kind == HELLO:
            if not self._spend(now):
                return None, "hello-rate"
            nb = secrets.token_bytes(NONCE)
            self._pending[nb] = (nh, now)
            while len(self._pending) > PENDING:
                self._pending.popitem(last=False)
            return self._send(CHALLENGE, key_id + nh + nb + proof(self.key, b"bridge", self.robot, nh, nb)), ""
        nb, mac = body[KEY_ID + NONCE:KEY_ID + 2 * NONCE], body[KEY_ID + 2 * NONCE:]
        issued = self._pending.get(nb)
        if issued is None or issued[0] != nh or now - issued[1] > PENDING_S:
            return None, "stale-proof"
        if not hmac.compare_digest(mac, proof(self.key, b"host", self.robot, nh, nb)):
            return None, "bad-proof"
        del self._pending[nb]  # (one proof per nonce: a replayed PROOF finds none)
        self.session = session_for(self.key, self.robot, nh, nb, host=False)
        self.peer = addr  # the session is the proven host's, at its address only
        self.seq = 0
        return self.seal(pack_bytes(WELCOME, self.robot, self.next_seq(), b"", self.session.id)), ""

    def next_seq(self) -> int:
        self.seq += 1
        return self.seq

    def seal(self, plain: bytes) -> bytes:
        return (self.session or PLAIN).seal(plain)

    def open(self, data: bytes, addr: tuple) -> tuple[bytes | None, str]:
        """Header and body of a datagram from ``addr`` this bridge may read: in the session, from the host that
        proved it, when it has a key; else intact."""
        if self.key is None:
            return PLAIN.open(data)
        if self.session is None:
            if len(data) < HEADER.size:
                return None, "length"
            return None, "other-session" if SEQ.unpack_from(data, SESSION_AT)[0] else "unauthenticated"
        plain, why = self.session.open(data)
        if plain is not None and addr != self.peer:  # authentic, and raced from elsewhere: not the host's copy
            return None, "other-address"
        return plain, why

    @property
    def id(self) -> int:
        """The session id datagrams sealed now carry (0: none, a link without a key)."""
        return self.session.id if self.session is not None else 0

    def refuse_unauthenticated(self, now: float) -> bytes | None:
        """A REFUSED telling a sender without the key that this bridge needs one (within the answers' budget)."""
        return self._refuse(KEY_NEEDED) if self._spend(now) else None

    def _spend(self, now: float) -> bool:
        """One answer to an unauthenticated datagram, at most ``ANSWERS_PER_S`` a second: a flood of them gets
        next to nothing back (the bridge is no amplifier, and its loop's time goes to its session)."""
        self._budget = min(ANSWERS_PER_S, self._budget + (now - self._refilled) * ANSWERS_PER_S)
        self._refilled = now
        if self._budget < 1.0:
            return False
        self._budget -= 1.0
        return True

    def _refuse(self, why: int) -> bytes:
        mine = bytes.fromhex(self.key.id) if self.key is not None else bytes(KEY_ID)
        return self._send(REFUSED, bytes([why]) + mine)

    def _send(self, kind: int, body: bytes) -> bytes:
        return PLAIN.seal(pack_bytes(kind, self.robot, self.next_seq(), body))


class HostHandshake:
    """The host's end of a handshake: what to send next (:meth:`next`) and what a reply makes of it
    (:meth:`take`): the session once the bridge welcomes it; a refusal or a bridge that cannot prove the key is
    said with :attr:`problem`."""

    def __init__(self, key: LinkKey, robot: int):
        self.key, self.robot = key, robot
        self.nh = secrets.token_bytes(NONCE)
        self.pending: Session | None = None  # derived from a proven challenge, not yet welcomed
        self.proof = b""
        self.problem: str | None = None  # the bridge refused: why, in words
        self.forged = 0  # challenges that did not prove the key (another party's, or another key's)

    def next(self, seq: int) -> bytes:
        """The datagram to send now: the HELLO, or the PROOF once a challenge was proven."""
        if self.pending is None:
            return PLAIN.seal(pack_bytes(HELLO, self.robot, seq, bytes.fromhex(self.key.id) + self.nh))
        return PLAIN.seal(pack_bytes(PROOF, self.robot, seq, self.proof))

    def take(self, data: bytes) -> Session | None:
        """A datagram from the bridge during the handshake: the session if it is the welcome."""
        if self.pending is not None and peek_kind(data) == WELCOME:
            plain, _ = self.pending.open(data)
            if plain is not None and HEADER.unpack_from(plain)[2] == WELCOME:
                return self.pending
            return None
        plain, _ = PLAIN.open(data)
        got = handshake_body(plain, self.robot) if plain is not None else None
        if got is None:
            return None
        kind, body = got
        if kind == REFUSED:
            self.problem = refusal(data, self.robot, self.key)
        elif kind == CHALLENGE and body[KEY_ID:KEY_ID + NONCE] == self.nh and self.pending is None:
            nb, mac = body[KEY_ID + NONCE:KEY_ID + 2 * NONCE], body[KEY_ID + 2 * NONCE:]
            if not hmac.compare_digest(mac, proof(self.key, b"bridge", self.robot, self.nh, nb)):
                self.forged += 1
                return None
            self.pending = session_for(self.key, self.robot, self.nh, nb, host=True)
            self.proof = bytes.fromhex(self.key.id) + self.nh + nb + proof(self.key, b"host", self.robot, self.nh, nb)
        return None


def refusal(data: bytes, robot: int, key: LinkKey | None) -> str | None:
    """Why the bridge refused a session, in words, if ``data`` is its REFUSED (``key``: this end's, if any)."""
    plain, _ = PLAIN.open(data)
    got = handshake_body(plain, robot) if plain is not None else None
    if got is None or got[0] != REFUSED:
        return None
    why, theirs = got[1][0], got[1][1:].hex()
    mine = f", this key's {key.id}" if key is not None else ""
    return f"the bridge {REFUSALS.get(why, 'refused the session')}" + (f" (its key id {theirs}{mine})"
                                                                        if why != NO_KEY else "")


def handshake(sock, addr: tuple, key: LinkKey, robot: int, next_seq, timeout: float = 5.0,
              resend_s: float = 0.05) -> Session:
    """Open a session with the bridge at ``addr`` over ``sock`` (``next_seq()``: this end's sequence numbers).

    Raises:
        LinkRefusedError: the bridge refused (no key, another key), or could not prove it holds this key.
        TimeoutError: no answer within ``timeout`` (wall time).
    """
    shake = HostHandshake(key, robot)
    until = time.monotonic() + timeout
    while time.monotonic() < until:
        sock.sendto(shake.next(next_seq()), addr)
        answer_by = min(until, time.monotonic() + resend_s)
        while wait_readable(sock, answer_by - time.monotonic()):
            try:
                data = sock.recv(65536)
            except (BlockingIOError, ConnectionRefusedError):
                break
            session = shake.take(data)
            if session is not None:
                return session
            if shake.problem is not None:
                raise LinkRefusedError(shake.problem)
    if shake.forged:
        raise LinkRefusedError(f"the bridge could not prove it holds key {key.id} ({shake.forged} challenges failed)")
    raise TimeoutError(f"no answer to the handshake within {timeout:g} s")


class LinkRefusedError(ValueError):
    """The bridge and this end do not share a key (its words say which side lacks it, naming key ids)."""
