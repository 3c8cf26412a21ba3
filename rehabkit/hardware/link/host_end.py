"""The host's end of the robot link: its socket, the bridge's address (nothing from elsewhere is read), the session
(with the robot's key: re-keyed every ``rekey_s`` of the link's time by a new handshake alongside the stream, which
switches to the new session once the bridge welcomes it; BYE at the end), one sequence count for all it sends, and
the lock-step clock's ticks, sent again when they go unanswered."""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Callable

import numpy as np

from rehabkit.hardware.config import LinkBusyError, LinkKeyError, LinkLostError
from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.protocol import CLOCK, HEADER, PLAIN, TICK, Receiver, encode, link_tick, pack_bytes
from rehabkit.hardware.security.handshake import (
    BYE,
    CHALLENGE,
    ENDINGS,
    HANDSHAKE,
    KEY_NEEDED,
    RESTART_S,
    HostHandshake,
    LinkRefusedError,
    handshake,
    peek_kind,
    refusal_words,
    refused,
)
from rehabkit.hardware.security.keys import LinkKey
from rehabkit.hardware.security.session import Session

LOCKSTEP_REPLY_S = 2.0  # wall time a lock-step bridge may take to answer one tick before the link counts as lost
RESEND_S = 0.05  # lock-step: a tick not answered within this (wall time) is sent again (it or its answer was lost)
REKEY_S = 120.0  # a session is re-keyed after this long (the link's time), as WireGuard's


class HostLink:
    """Datagrams to and from the bridge at ``host``:``port`` for robot ``robot_id``; with ``key``, in an authenticated
    session (:meth:`open_session`) and from the bridge's address only. ``rx`` counts what is dropped."""

    def __init__(self, host: str, port: int, robot_id: int, key: LinkKey | None, rx: Receiver, timestep: float,
                 rekey_s: float = REKEY_S):
        self.addr = (socket.gethostbyname(host), port)  # (as datagrams from it say where they came from)
        self.robot_id, self.key, self.rx, self.timestep, self.rekey_s = robot_id, key, rx, timestep, rekey_s
        self.previous: Session | None = None  # the session before the newest re-key (its states may be in flight)
        self._rekey: HostHandshake | None = None  # a re-key under way
        self._keyed_at: float | None = None  # the link's time the session began (its first datagram)
        self._rekey_sent = self._rekey_began = 0.0
        self.rekeys = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.link = PLAIN  # the session once the handshake is done
        self.seq = 0
        self.clock, self.answered = 0, -1.0  # lock-step: ticks sent, the newest tick's end the bridge answered
        self.refused: str | None = None  # the bridge said it needs a key this host does not have
        # the bridge ended this host's session (its BYE, sealed in it): another host's took it over, "keypad" (the
        # person at the robot allowed it) or "silent" (after this host's fell silent)
        self.ended: str | None = None
        self._last: tuple | None = None  # lock-step: what carried the newest tick, to send again if lost

    @property
    def where(self) -> str:
        return f"udp://{self.addr[0]}:{self.addr[1]}"

    def next_seq(self) -> int:
        self.seq += 1  # (one count for everything this end sends: a session's nonces never repeat)
        return self.seq

    def open_session(self) -> None:
        """The handshake with the bridge, with the robot's key: every datagram from now on is in the session."""
        try:
            self.link = handshake(self.sock, self.addr, self.key, self.robot_id, self.next_seq)
            self.first_id = self.link.id
        except LinkRefusedError as exc:
            if exc.reason == "busy":  # (the keys match: another host's run holds the bridge)
                raise LinkBusyError(self.where, exc.words) from None
            raise LinkKeyError(self.where, str(self.key.path), exc.words, exc.reason, exc.key_id) from None
        except TimeoutError:
            raise LinkLostError(f"the bridge at {self.where} does not answer a handshake (is `rehabkit bridge` running "
                                "there, for this robot and robot_id, with its --key?)") from None

    def send(self, kind: int, values: np.ndarray, sent_at: float, status: int = 0) -> None:
        """A datagram to the bridge, sealed in the session if there is one (kept, if it carries a tick)."""
        what = (kind, values, sent_at, status)
        if kind == CLOCK or status & TICK:
            self._last = what
        self._transmit(what)
        if self.link is not PLAIN:
            self._rekey_due(sent_at)

    def _rekey_due(self, t: float) -> None:
        """Re-key when the session is ``rekey_s`` old (``t``: the link's time now): a handshake alongside the stream,
        its HELLO (then PROOF) sent again every ``RESEND_S`` until the bridge welcomes the new session."""
        if self._keyed_at is None:
            self._keyed_at = t
        if self._rekey is None and t - self._keyed_at >= self.rekey_s or \
                self._rekey is not None and self._rekey.pending is None and t - self._rekey_began > RESTART_S:
            self._rekey, self._rekey_began, self._rekey_sent = HostHandshake(self.key, self.robot_id), t, -1e9
        if self._rekey is not None and t - self._rekey_sent >= RESEND_S:
            self._rekey_sent = t
            self.sock.sendto(self._rekey.next(self.next_seq()), self.addr)

    def _rekeyed(self, session: Session) -> None:
        self.previous, self.link, self._rekey, self._keyed_at = self.link, session, None, None
        self.rekeys += 1

    def _transmit(self, what: tuple) -> None:
        kind, values, sent_at, status = what
        self.sock.sendto(encode(kind, self.robot_id, self.next_seq(), values, sent_at=sent_at, status=status,
                                link=self.link), self.addr)

    def tick_lockstep(self, receive: Callable[[], None], timeout: float = LOCKSTEP_REPLY_S, sent: bool = False) -> bool:
        """Lock-step: tell the bridge to tick at the link's time (``sent``: a command carrying the tick has gone),
        wait (in wall time) until it says it has, ``receive``-ing what came meanwhile, and ask again each
        ``RESEND_S`` without an answer (a datagram lost to a full socket buffer); the clock advances one tick.
        False if it did not answer in ``timeout``."""
        t = self.clock * self.timestep
        if not sent:
            self.send(CLOCK, np.zeros(0), t)
        self.clock += 1
        done = t + 0.5 * self.timestep  # the bridge answers with the time its tick ends, t + its timestep
        until = time.monotonic() + timeout
        while self.answered < done:
            now = time.monotonic()
            if now >= until or self.ended is not None:
                return False
            if not wait_readable(self.sock, min(until, now + RESEND_S) - now):
                self._transmit(self._last)  # the same tick again: the bridge ticks once, answers again
                continue
            receive()
        return True

    def arrived(self, now: Callable[[], float], lockstep: bool) -> list[tuple[bytes, float]]:
        """What came, opened (with the time each was taken in): a refusal noted (:attr:`refused`), what fails
        counted by reason, the lock-step clock's answers taken (a bare clock carries no state: not returned)."""
        out = []
        while True:
            try:
                data, came_from = self.sock.recvfrom(65536)
            except (BlockingIOError, ConnectionRefusedError):
                return out
            t = now()
            if came_from != self.addr:  # (checked first: nothing from elsewhere is opened, keyed or not)
                self.rx.dropped["other-address"] += 1
                continue
            if peek_kind(data) in HANDSHAKE:
                self._handshake(data)
                continue
            plain, why = self._open(data)
            if plain is None:
                self.rx.dropped[why] += 1
                continue
            if plain[3] == BYE:  # (sealed in this host's session: the bridge's word, no one else's)
                self.ended = ENDINGS.get(plain[HEADER.size] if len(plain) > HEADER.size else 0, "ended")
                continue
            if lockstep and (tick := link_tick(plain, self.robot_id)) is not None:
                self.answered = max(self.answered, tick[0])
                if tick[1]:
                    continue
            out.append((plain, t))

    def _handshake(self, data: bytes) -> None:
        """Outside the first handshake: a re-key's answers, and a keyless host told that the bridge needs a key."""
        if self._rekey is not None:
            proven = self._rekey.pending
            session = self._rekey.take(data)
            if session is not None:
                self._rekeyed(session)
            elif proven is None and self._rekey.pending is not None and peek_kind(data) == CHALLENGE:
                self._rekey_sent = -1e9  # (its PROOF goes with the next datagram)
        elif self.key is None and (got := refused(data, self.robot_id)) is not None and got[0] == KEY_NEEDED:
            self.refused = refusal_words(KEY_NEEDED, None)

    def _open(self, data: bytes) -> tuple[bytes | None, str]:
        """In the session, or the one before the newest re-key, or the one a re-key is making (its WELCOME lost)."""
        plain, why = self.link.open(data)
        if why == "other-session":
            if self.previous is not None:
                plain, why = self.previous.open(data)
            if plain is None and self._rekey is not None and self._rekey.pending is not None:
                plain, why = self._rekey.pending.open(data)
                if plain is not None:
                    self._rekeyed(self._rekey.pending)
        return plain, why

    def provenance(self) -> dict[str, str]:
        """The bridge and the session's key id (the safety log's run record)."""
        if self.link is PLAIN:
            return {"bridge": self.where, "session": "none: a link without a key (loopback)"}
        return {"bridge": self.where, "session": f"{self.first_id:08x}", "key_id": self.key.id,
                "rekeys": str(self.rekeys)}

    def close(self) -> None:
        """The session ends with a BYE (the bridge need not wait to let the next host in), the socket closes."""
        if self.link is not PLAIN:
            with contextlib.suppress(OSError):
                self.sock.sendto(self.link.seal(pack_bytes(BYE, self.robot_id, self.next_seq(), b"", self.link.id)),
                                 self.addr)
        self.sock.close()
