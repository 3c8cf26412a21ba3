"""The bridge's end of the handshake (:mod:`rehabkit.hardware.security.handshake`: the messages, and what strangers
cannot spend) and the gate that keeps the session it opens.

One session at a time, the proven host's, at its address only; under the robot's key it may drive (its ``right``
"drive"), under the bridge's clearing key, if it has one, only clear a latched e-stop ("clear"). Its host re-keys it
on a schedule (a new handshake from the same address while the session runs: the new session takes over, the old one
still opens what was in flight until the new one has opened ``WINDOW`` datagrams); a HELLO from another address
while the session is live (an authentic datagram within ``LIVE_S``) is refused (``BUSY``) unless the person at the
bridge allowed one (:meth:`BridgeGate.allow`); the host's BYE ends it at once. A new key (:meth:`BridgeGate.rekey`,
on SIGHUP) ends every session made under the old one.
"""

from __future__ import annotations

import hmac
import time
from collections import OrderedDict
from dataclasses import dataclass

from rehabkit.hardware.link.protocol import HEADER, PLAIN, SEQ, SESSION_AT, pack_bytes
from rehabkit.hardware.security.handshake import (
    BUSY,
    CHALLENGE,
    HELLO,
    KEY_NEEDED,
    NO_KEY,
    OTHER_KEY,
    PROOF,
    REF,
    REFUSED,
    WELCOME,
    handshake_body,
)
from rehabkit.hardware.security.keys import LinkKey
from rehabkit.hardware.security.session import (
    MAC1,
    PUBLIC,
    WINDOW,
    Session,
    ephemeral,
    exchange,
    mac1,
    mac1_key,
    session_for,
    warm_up,
)

ANSWERS_PER_S = 5.0  # answers (challenges, refusals) to one source (address and port) outside a session, a second
SOURCES = 256  # sources whose budgets are kept (the least recent forgotten: a new one starts with a full budget)
PENDING = 16  # challenges issued and not yet proven, kept at most
PENDING_S = 5.0  # how long a challenge may be proven
SEEN = 1024  # the newest HELLOs' Eh kept: one seen before is answered only as it was (no new key pair)
LIVE_S = 1.0  # a session with an authentic datagram within this is live: no other host takes it over
ALLOW_S = 30.0  # the person at the bridge allows a new host to take over within this


@dataclass
class _Pending:
    addr: tuple
    session: Session
    proof: bytes  # the host's, expected
    challenge: bytes  # the datagram sent (sent again, unchanged, to the same address)
    issued: float


class BridgeGate:
    """Answers handshakes, keeps the proven session, opens datagrams in it, counts nothing itself (the reasons it
    returns are counted by the caller)."""

    def __init__(self, key: LinkKey | None, robot: int, clear_key: LinkKey | None = None):
        self.key, self.robot, self.clear_key = key, robot, clear_key
        self.mac_key = mac1_key(key) if key is not None else b""
        self.clear_mac = mac1_key(clear_key) if clear_key is not None else None
        if key is not None:  # (the cryptography's first use is slow: here, not in the loop's first handshake)
            warm_up(key, robot)
        self.session: Session | None = None
        self.previous: Session | None = None  # the session before a re-key, while its datagrams may be in flight
        self.peer: tuple | None = None  # the address that proved the session
        self.heard = -1e9  # when an authentic datagram of the session last came (time.monotonic)
        self.allowed_until = -1e9  # the person at the bridge allowed another host to take over until then
        self._pending: OrderedDict[bytes, _Pending] = OrderedDict()  # Eh → the challenge made for it
        self._seen: OrderedDict[bytes, None] = OrderedDict()
        self._welcomed: tuple[bytes, tuple, bytes] | None = None  # (PROOF, from, WELCOME) of the newest session
        self._budgets: OrderedDict[tuple, tuple[float, float]] = OrderedDict()  # source → (answers left, at)
        self.seq = 0
        self.rekeys = 0  # sessions re-keyed by their host
        self._opened = 0  # datagrams the session opened since it was made
        # the session a new host's took over, its host, and whether it was live (the keypad allowed it), until the
        # link has told that host (BridgeLink.open)
        self.taken_over: tuple[Session, tuple, bool] | None = None

    @property
    def challenges(self) -> int:
        """Challenges issued and not yet proven (state kept for key holders only)."""
        return len(self._pending)

    def live(self, now: float) -> bool:
        return self.session is not None and now - self.heard < LIVE_S

    def allow(self, now: float) -> None:
        """The person at the bridge lets a new host take the session over (within ``ALLOW_S``)."""
        self.allowed_until = now + ALLOW_S

    def reply(self, data: bytes, addr: tuple, now: float | None = None) -> tuple[bytes | None, str]:
        """A handshake datagram from ``addr``: the reply to send back (or None) and, if it was refused, why
        (counted by the caller); a proven PROOF makes a new session (:attr:`session`)."""
        now = time.monotonic() if now is None else now
        plain, why = PLAIN.open(data)
        got = handshake_body(plain, self.robot) if plain is not None else None
        if got is None or got[0] not in (HELLO, PROOF):
            return None, why or "handshake"
        kind, body = got
        if self.key is None:
            return self._refuse(NO_KEY, body, addr, now), "no-key"
        eh = body[:PUBLIC]
        if kind == HELLO:
            tag = mac1(self.mac_key, plain[:-MAC1])
            if hmac.compare_digest(body[-MAC1:], tag):
                return self._hello(eh, body, addr, now, self.key)
            if self.clear_mac is not None and hmac.compare_digest(body[-MAC1:], mac1(self.clear_mac, plain[:-MAC1])):
                return self._hello(eh, body, addr, now, self.clear_key)  # (a session with the right to clear only)
            return self._refuse(OTHER_KEY, body, addr, now), "other-key"  # (no state, no key pair: a refusal)
        welcomed = self._welcomed
        if welcomed is not None and welcomed[1] == addr and hmac.compare_digest(welcomed[0], body):
            return (welcomed[2] if self._spend(addr, now) else None), "proof-again"  # (its WELCOME was lost)
        pending = self._pending.get(eh)
        if pending is None or now - pending.issued > PENDING_S:
            return None, "stale-proof"
        if pending.addr != addr:  # (tied to the HELLO's source: checked before anything is computed)
            return None, "other-address"
        del self._pending[eh]  # one PROOF per challenge, right or wrong
        if not hmac.compare_digest(body[PUBLIC:], pending.proof):
            return None, "bad-proof"
        if self.live(now) and addr != self.peer and now > self.allowed_until:
            return self._refuse(BUSY, body, addr, now), "busy"
        rekey = self.live(now) and addr == self.peer
        if not rekey and self.session is not None and addr != self.peer:  # another host's: its host is to be told
            self.taken_over = (self.session, self.peer, self.live(now))
        self.previous = self.session if rekey else None
        self.rekeys += rekey
        self.session, self.peer, self.heard, self._opened = pending.session, addr, now, 0
        self.allowed_until = -1e9 if not rekey else self.allowed_until
        welcome = self.seal(pack_bytes(WELCOME, self.robot, self.next_seq(), b"", self.session.id))
        self._welcomed = (body, addr, welcome)
        return welcome, ""

    def _hello(self, eh: bytes, body: bytes, addr: tuple, now: float, key: LinkKey) -> tuple[bytes | None, str]:
        pending = self._pending.get(eh)
        if pending is not None:  # the host's HELLO again (its CHALLENGE lost), or a replay from elsewhere
            if pending.addr != addr:
                return None, "other-address"
            return (pending.challenge if self._spend(addr, now) else None), "hello-again"
        if eh in self._seen:  # a replay of a HELLO whose challenge was proven, or spent
            return None, "replayed-hello"
        if self.live(now) and addr != self.peer and now > self.allowed_until:
            return self._refuse(BUSY, body, addr, now), "busy"
        if not self._spend(addr, now):
            return None, "hello-rate"
        private, eb = ephemeral()
        dh = exchange(private, eh)
        if dh is None:
            return None, "bad-hello"
        session, bridge_proof, host_proof = session_for(key, self.robot, eh, eb, dh, host=False)
        session.right = "clear" if key is self.clear_key else "drive"
        challenge = PLAIN.seal(pack_bytes(CHALLENGE, self.robot, self.next_seq(), eb + bridge_proof))
        self._pending[eh] = _Pending(addr, session, host_proof, challenge, now)
        self._seen[eh] = None
        while len(self._pending) > PENDING:
            self._pending.popitem(last=False)
        while len(self._seen) > SEEN:
            self._seen.popitem(last=False)
        return challenge, ""

    def next_seq(self) -> int:
        self.seq += 1
        return self.seq

    def seal(self, plain: bytes) -> bytes:
        return (self.session or PLAIN).seal(plain)

    def open(self, data: bytes, addr: tuple) -> tuple[bytes | None, str]:
        """Header and body of a datagram from ``addr`` this bridge may read: with a key, from the host that proved
        the session (checked first: nothing from elsewhere is decrypted), in it (or the one it re-keyed, while
        its datagrams may be in flight); without, intact."""
        if self.key is None:
            return PLAIN.open(data)
        if self.session is None:
            if len(data) < HEADER.size:
                return None, "length"
            return None, "other-session" if SEQ.unpack_from(data, SESSION_AT)[0] else "unauthenticated"
        if addr != self.peer:
            return None, "other-address"
        plain, why = self.session.open(data)
        if why == "other-session" and self.previous is not None:
            plain, why = self.previous.open(data)
        elif plain is not None:
            self._opened += 1
            if self._opened > WINDOW:  # (the host has long moved to the new session: the old one's keys go)
                self.previous = None
        if plain is not None:
            self.heard = time.monotonic()
        return plain, why

    def end(self) -> None:
        """The session ends (its host said BYE, or the key changed): the next host's proof makes the next."""
        self.session = self.previous = self.peer = self._welcomed = None
        self.heard = -1e9

    def rekey(self, key: LinkKey, clear_key: LinkKey | None = None) -> None:
        """A new key (rotated; and the clearing key, if any): every session and challenge made under the old ones
        ends."""
        self.end()
        self.key, self.mac_key = key, mac1_key(key)
        self.clear_key, self.clear_mac = clear_key, mac1_key(clear_key) if clear_key is not None else None
        self._pending.clear()
        warm_up(key, self.robot)

    @property
    def id(self) -> int:
        """The session id datagrams sealed now carry (0: none, a link without a key)."""
        return self.session.id if self.session is not None else 0

    def refuse_unauthenticated(self, data: bytes, addr: tuple, now: float) -> bytes | None:
        """A REFUSED telling a sender without the key that this bridge needs one (within its budget)."""
        return self._refuse(KEY_NEEDED, data[HEADER.size:], addr, now, size=len(data))

    def _spend(self, addr: tuple, now: float) -> bool:
        """One answer to ``addr`` outside a session, at most ``ANSWERS_PER_S`` a second for each source: a flood
        from elsewhere spends its own budget, never the host's. The live session's host (re-keying it) spends none."""
        if addr == self.peer and self.live(now):
            return True
        left, at = self._budgets.pop(addr, (ANSWERS_PER_S, now))
        left = min(ANSWERS_PER_S, left + (now - at) * ANSWERS_PER_S)
        self._budgets[addr] = (left - 1.0 if left >= 1.0 else left, now)
        while len(self._budgets) > SOURCES:
            self._budgets.popitem(last=False)
        return left >= 1.0

    def _refuse(self, why: int, body: bytes, addr: tuple, now: float, size: int | None = None) -> bytes | None:
        """A REFUSED naming the refused datagram by its body's first bytes, if its source's budget allows and it
        is no bigger than what it answers (``size``)."""
        answer = PLAIN.seal(pack_bytes(REFUSED, self.robot, self.seq + 1, bytes([why]) + body[:REF].ljust(REF, b"\0")))
        if size is not None and len(answer) > size or not self._spend(addr, now):
            return None
        self.seq += 1
        return answer
