"""The handshake that opens an authenticated session, its messages and the host's end of it (the bridge's:
:class:`~rehabkit.hardware.security.gate.BridgeGate`).

Each message is a datagram of its own kind, its body bytes (``K`` the robot's key; ``Eh``, ``Eb`` the host's and the
bridge's ephemeral X25519 public keys, fresh for each handshake; sizes in bytes with the 42-byte header)::

    host   → bridge   HELLO      Eh · 16 zero bytes · MAC1            110   MAC1: HMAC(HMAC(K, "mac1"), all before it)
    bridge → host     CHALLENGE  Eb · the bridge's proof              110
    host   → bridge   PROOF      Eh · the host's proof                110
    bridge → host     WELCOME    (empty, sealed in the new session)    58
    bridge → host     REFUSED    why · the first 8 bytes of the refused datagram's body (a HELLO's: Eh)   55
    host   → bridge   BYE        (empty, sealed in the session: it ends; the next host need not wait)
    bridge → host     BYE        why (1 byte), sealed in the session another host's took over: it has ended

Both ends derive the session and the two proofs from ``K``, ``Eh``, ``Eb`` and the X25519 of the two
(:func:`~rehabkit.hardware.security.session.session_for`); each drops its ephemeral private key once the session is
made, so a key file stolen later opens no captured session (forward secrecy). A proof binds both ephemeral keys and
the key: neither can be replayed into another handshake.

What strangers cannot spend (WireGuard's MAC1 and cookie ideas, DTLS's "no answer bigger than the request"):

- A HELLO's MAC1 is checked before anything else is done: only a key holder makes one; without it no CHALLENGE is
  made, no state kept (a wrong MAC1 is at most told REFUSED, "another key", from its source's small budget).
- Every answer outside a session (CHALLENGE, REFUSED) comes from a budget of its source's own address and port
  (``ANSWERS_PER_S``): a flood from elsewhere spends its own, never the host's; none is bigger than its request
  (the HELLO is padded), and no answer names a key id.
- A CHALLENGE is tied to the address its HELLO came from and takes one PROOF (right or wrong): a PROOF from
  elsewhere is refused before anything is computed, and a HELLO seen before (a replay) is answered only to its own
  address, with the CHALLENGE already made (no new key pair).
- The host takes a REFUSED only from the bridge's address, naming its own HELLO's ``Eh``.
"""

from __future__ import annotations

import hmac
import time

from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.protocol import HEADER, MAGIC, PLAIN, VERSION, pack_bytes
from rehabkit.hardware.security.keys import LinkKey
from rehabkit.hardware.security.session import (
    MAC,
    MAC1,
    PUBLIC,
    Session,
    ephemeral,
    exchange,
    mac1,
    mac1_key,
    session_for,
)

HELLO, CHALLENGE, PROOF, WELCOME, REFUSED, BYE = 5, 6, 7, 8, 9, 10
REFUSAL_GRACE_S = 0.25  # a REFUSED is taken once no proven challenge came this long after it
HANDSHAKE = frozenset((HELLO, CHALLENGE, PROOF, WELCOME, REFUSED))
PAD = 16  # a HELLO's zero bytes: it is as big as the CHALLENGE it asks for
REF = 8  # a REFUSED names what it refuses by this many bytes of its body
RESTART_S = 1.0  # a handshake not welcomed within this starts afresh (new ephemeral keys)
# REFUSED's reasons, and the host's words for them
NO_KEY, OTHER_KEY, KEY_NEEDED, BUSY = 1, 2, 3, 4
REASONS = {NO_KEY: "no-key", OTHER_KEY: "other-key", KEY_NEEDED: "key-needed", BUSY: "busy"}
# a bridge's BYE: why the session ended (another host's session took it over: allowed at the robot's keypad while it
# was live, or after it fell silent)
TAKEN_OVER, REPLACED = 1, 2
ENDINGS = {TAKEN_OVER: "keypad", REPLACED: "silent"}
_BODY = {HELLO: PUBLIC + PAD + MAC1, CHALLENGE: PUBLIC + MAC, PROOF: PUBLIC + MAC, REFUSED: 1 + REF}


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


def refused(data: bytes, robot: int) -> tuple[int, bytes] | None:
    """A REFUSED's reason and the bytes naming what it refuses, if ``data`` is one for ``robot``."""
    plain, _ = PLAIN.open(data)
    got = handshake_body(plain, robot) if plain is not None else None
    if got is None or got[0] != REFUSED:
        return None
    return got[1][0], got[1][1:]


class HostHandshake:
    """The host's end of a handshake: what to send next (:meth:`next`) and what a reply makes of it
    (:meth:`take`): the session once the bridge welcomes it (or a datagram of it arrives first); a refusal is kept
    as :attr:`refusal` (its reason), a bridge that cannot prove the key counted in :attr:`forged`."""

    def __init__(self, key: LinkKey, robot: int, mac_key: bytes | None = None):
        self.key, self.robot = key, robot
        self.mac_key = mac_key or mac1_key(key)
        self._private, self.eh = ephemeral()
        self.pending: Session | None = None  # derived from a proven challenge, not yet welcomed
        self.proof = b""
        self.refusal: int | None = None  # the bridge refused this HELLO: why (NO_KEY, OTHER_KEY, ...)
        self.forged = 0  # challenges that did not prove the key (another party's, or another key's)
        self.started = time.monotonic()

    def next(self, seq: int) -> bytes:
        """The datagram to send now: the HELLO, or the PROOF once a challenge was proven."""
        if self.pending is None:
            plain = pack_bytes(HELLO, self.robot, seq, self.eh + bytes(PAD) + bytes(MAC1))
            return PLAIN.seal(plain[:-MAC1] + mac1(self.mac_key, plain[:-MAC1]))
        return PLAIN.seal(pack_bytes(PROOF, self.robot, seq, self.eh + self.proof))

    def take(self, data: bytes) -> Session | None:
        """A datagram from the bridge's address during the handshake: the session if it is the welcome (or any
        datagram sealed in it: the welcome was lost)."""
        if self.pending is not None and peek_kind(data) not in (CHALLENGE, REFUSED):
            plain, _ = self.pending.open(data)
            if plain is not None:
                self._private = None  # (the session is made: nothing of the exchange is kept)
                return self.pending
            return None
        plain, _ = PLAIN.open(data)
        got = handshake_body(plain, self.robot) if plain is not None else None
        if got is None:
            return None
        kind, body = got
        if kind == REFUSED and body[1:] == self.eh[:REF]:  # (bound to this HELLO: a blind forger cannot name it)
            self.refusal = body[0]
        elif kind == CHALLENGE and self.pending is None:
            eb, theirs = body[:PUBLIC], body[PUBLIC:]
            dh = exchange(self._private, eb)
            if dh is None:
                self.forged += 1
                return None
            session, bridge_proof, host_proof = session_for(self.key, self.robot, self.eh, eb, dh, host=True)
            if not hmac.compare_digest(theirs, bridge_proof):
                self.forged += 1
                return None
            self.pending, self.proof = session, host_proof
        return None


def refusal_words(reason: int, key: LinkKey | None) -> str:
    """Why the bridge refused a session, in words (``key``: this end's, if any)."""
    mine = f" (this key's id {key.id}; the bridge's is on its console and in its --stats)" if key else ""
    return {NO_KEY: "the bridge has no key (it was started without --key)",
            OTHER_KEY: f"the bridge holds another key{mine}",
            KEY_NEEDED: "the bridge needs a key (it was started with --key)",
            BUSY: "the bridge serves another host's live session: a new one is let in once it ends, or when the "
                  "person at the robot allows it (its keypad's a)"}.get(reason, "the bridge refused the session")


def handshake(sock, addr: tuple, key: LinkKey, robot: int, next_seq, timeout: float = 5.0,
              resend_s: float = 0.05) -> Session:
    """Open a session with the bridge at ``addr`` over ``sock`` (``next_seq()``: this end's sequence numbers); what
    comes from elsewhere is not read as the bridge's.

    Raises:
        LinkRefusedError: the bridge refused (no key, another key; another host's live session still, at the
            timeout), or could not prove it holds this key.
        TimeoutError: no answer within ``timeout`` (wall time).
    """
    mac_key = mac1_key(key)
    shake = HostHandshake(key, robot, mac_key)
    until = time.monotonic() + timeout
    forged, busy = 0, False
    refused: tuple[int, float] | None = None  # the first refusal and when its grace ends

    def refuse(reason: int) -> LinkRefusedError:
        return LinkRefusedError(REASONS.get(reason, "refused"), key.id, refusal_words(reason, key))

    while time.monotonic() < until:
        if refused is not None and time.monotonic() >= refused[1]:
            raise refuse(refused[0])
        if shake.pending is None and time.monotonic() - shake.started > RESTART_S:  # afresh: new ephemeral keys
            forged += shake.forged
            shake = HostHandshake(key, robot, mac_key)
        sock.sendto(shake.next(next_seq()), addr)
        proven = shake.pending is not None
        answer_by = min(until, time.monotonic() + resend_s, refused[1] if refused is not None else until)
        while wait_readable(sock, answer_by - time.monotonic()):
            try:
                data, came_from = sock.recvfrom(65536)
            except (BlockingIOError, ConnectionRefusedError):
                break
            if came_from != addr:  # (a REFUSED or a CHALLENGE from elsewhere is no bridge's)
                continue
            session = shake.take(data)
            if session is not None:
                return session
            if shake.refusal == BUSY:  # another host's session: it may be ending (its BYE), or be let go at the
                busy, shake.refusal = True, None  # robot: asked again until the timeout
            elif shake.refusal is not None:  # (taken once no challenge proven came for REFUSAL_GRACE_S: one who
                # can watch the link and spoof the bridge can forge a REFUSED naming the HELLO — the bridge's own
                # challenge, right behind it, wins)
                refused = refused or (shake.refusal, time.monotonic() + REFUSAL_GRACE_S)
                shake.refusal = None
            if not proven and shake.pending is not None:
                break  # (the challenge proven: the PROOF goes at once)
    if refused is not None:
        raise refuse(refused[0])
    if forged + shake.forged:
        raise LinkRefusedError("forged", key.id, f"the bridge could not prove it holds key {key.id} "
                               f"({forged + shake.forged} challenges failed)")
    if busy:
        raise LinkRefusedError("busy", key.id, refusal_words(BUSY, key))
    raise TimeoutError(f"no answer to the handshake within {timeout:g} s")


class LinkRefusedError(ValueError):
    """The bridge refused this end's session: ``reason`` (no-key, other-key, key-needed, busy; forged: it could
    not prove the key), ``key_id`` (this end's), ``words`` (said so)."""

    def __init__(self, reason: str, key_id: str | None, words: str):
        self.reason, self.key_id, self.words = reason, key_id, words
        super().__init__(words)
