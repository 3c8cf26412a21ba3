"""The bridge's end of the robot link: its UDP sockets, the gate that answers handshakes and opens datagrams
(:class:`~rehabkit.hardware.security.gate.BridgeGate`), the command receiver, and the count of all it refused.

An authenticated session gets a socket of its own, on the same port and connected to the host that proved it: the
kernel hands the host's datagrams to it and everything else to the open socket, so a flood from elsewhere queues
apart from the session's and cannot crowd its datagrams out of one buffer.

Whatever arrives, the bridge keeps its clock: each tick reads at most ``PER_TICK`` datagrams from each socket, one
from each in turn, and only until a time it is given (:meth:`BridgeLink.gather`: until the next deadline, after the
tick's plant step, watchdog and state out; :meth:`BridgeLink.arrived`: for ``READ_S``). A flood beyond that (even one
spoofing the host's own address, which reaches the session's socket) stays in the kernel's buffer, and what does not
fit there is dropped by the kernel: the host's commands among it too, and then the watchdog holds the robot, on time.
"""

from __future__ import annotations

import contextlib
import select
import socket
import sys
import time
from collections import Counter

from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.protocol import CMD_RESET, COMMAND, SEQ, SESSION_AT, Receiver, encode, pack_bytes
from rehabkit.hardware.security.events import SecurityLog
from rehabkit.hardware.security.gate import BridgeGate
from rehabkit.hardware.security.handshake import BYE, HANDSHAKE, REPLACED, TAKEN_OVER, peek_kind
from rehabkit.hardware.security.keys import LinkKey

PER_TICK = 32  # datagrams read from each socket (the session's, the open one) at most, per tick
READ_S = 2.5e-4  # a tick that reads what arrived (arrived()) reads for this long at most
TOLD = 3  # a host whose session another host's took over is told so this many times at most


class BridgeLink:
    """Where the bridge listens (``host``, ``port``; 0: any free port), for ``robot_id`` with ``joints`` commanded
    joints; given ``key``, in authenticated sessions only."""

    def __init__(self, robot_id: int, joints: int, host: str = "127.0.0.1", port: int = 0,
                 key: LinkKey | None = None, clear_key: LinkKey | None = None, log: SecurityLog | None = None):
        self.robot_id = robot_id
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)  # (the session's socket shares the port)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.host, self.port = host, self.sock.getsockname()[1]
        self.session_sock: socket.socket | None = None  # connected to the proven host
        # with a key a proven handshake opens a session; without, a host's reset does (a new run, a new host
        # process, numbers its commands from 1 again)
        self.gate = BridgeGate(key, robot_id, clear_key)
        self.log = log  # refused attempts, as they happen (rate-limited)
        self.rx = Receiver(COMMAND, robot_id, joints, restart=0 if key is not None else CMD_RESET)
        self.sessions: list[dict] = []  # each authenticated session: when, from where, its id and key id
        self.opened_from: Counter = Counter()  # datagrams let in, by the address they came from
        self._told: list | None = None  # [session, host, why, times told] of the session another host's took over

    @property
    def key_id(self) -> str:
        """The key of the session in use, as the safety log and the latch file record it."""
        return self.gate.session.key_id if self.gate.session is not None else "none (a link without a key)"

    @property
    def right(self) -> str:
        """What the session in use may do: "drive", or "clear" (a session under the clearing key)."""
        return self.gate.session.right if self.gate.session is not None else "drive"

    @property
    def session_id(self) -> str:
        return f"{self.gate.id:08x}" if self.gate.session is not None else "none"

    def arrived(self, until: float | None = None) -> list[tuple[bytes, tuple]]:
        """What came since the last tick, opened (handshakes answered, the rest refused and counted): at most
        ``PER_TICK`` from each socket, one from each in turn, and none read after ``until`` (``time.monotonic``;
        default ``READ_S`` from now)."""
        until = time.monotonic() + READ_S if until is None else until
        out: list[tuple[bytes, tuple]] = []
        taken: Counter = Counter()
        while True:  # (one round always: a process descheduled past ``until`` still takes what had arrived)
            socks = self._readable(taken)
            if not socks:
                return out
            for sock in socks:
                self._read_one(sock, taken, out)
            if time.monotonic() >= until:
                return out

    def gather(self, until: float) -> list[tuple[bytes, tuple]]:
        """What comes until ``until`` (``time.monotonic``), read as it comes and opened, asleep between datagrams:
        the loop's time between its ticks. At most ``PER_TICK`` from each socket (then it sleeps on the others, or
        returns: the rest waits in the kernel's buffer)."""
        out: list[tuple[bytes, tuple]] = []
        taken: Counter = Counter()
        while (left := until - time.monotonic()) > 0:
            socks = [s for s in (self.session_sock, self.sock) if s is not None and taken[s] < PER_TICK]
            if not socks:
                return out
            for sock in select.select(socks, [], [], left)[0]:
                if sock is self.sock or sock is self.session_sock:  # (a new session may have replaced its socket)
                    self._read_one(sock, taken, out, wait=True)
        return out

    def _readable(self, taken: Counter) -> list[socket.socket]:
        return [s for s in (self.session_sock, self.sock) if s is not None and taken[s] < PER_TICK]

    def _read_one(self, sock: socket.socket, taken: Counter, out: list, wait: bool = False) -> None:
        """One datagram from ``sock`` opened into ``out`` (counted in ``taken``; a socket with none left is done)."""
        if sock is not self.sock and sock is not self.session_sock:  # (replaced by a new session's meanwhile)
            return
        taken[sock] += 1
        try:
            data, addr = sock.recvfrom(65536)
        except BlockingIOError:
            if not wait:
                taken[sock] = PER_TICK  # empty: read no more from it this tick
            return
        except ConnectionRefusedError:  # (the session's host is gone: its socket says so, once)
            return
        if (plain := self.open(data, addr)) is not None:
            out.append((plain, addr))

    def next(self, timeout: float, also: int | None = None) -> tuple[bytes, tuple] | None:
        """The next datagram to come (the session's first), waiting up to ``timeout``; None if none came, or if
        ``also`` (a file descriptor: the keypad's) became readable first."""
        socks = [self.sock] if self.session_sock is None else [self.session_sock, self.sock]
        if not wait_readable(socks if also is None else [*socks, also], timeout):
            return None
        for sock in socks:
            try:
                return sock.recvfrom(65536)
            except (BlockingIOError, ConnectionRefusedError):
                continue
        return None

    def close(self) -> None:
        for sock in (self.sock, self.session_sock):
            if sock is not None:
                sock.close()
        if self.log is not None:
            self.log.close()

    def open(self, data: bytes, addr: tuple) -> bytes | None:
        """A datagram's header and body if it is one to read (intact; with a key, authentic and not seen before);
        a handshake is answered here, at once; what is refused is counted by reason."""
        if peek_kind(data) in HANDSHAKE:
            was, rekeys = self.gate.session, self.gate.rekeys
            reply, why = self.gate.reply(data, addr)
            if why:
                self.refused(addr, f"handshake-{why}")
            if self.gate.session is not was and self.gate.rekeys == rekeys:  # a new host's session, proven: its
                self.rx.last_seq = None  # numbers start afresh, its socket its own
                self._connect(addr)
                self.sessions.append({"at": time.time(), "from": f"{addr[0]}:{addr[1]}",
                                      "session": f"{self.gate.id:08x}", "key_id": self.key_id})
                print(f"bridge: session {self.gate.id:08x} from {addr[0]}:{addr[1]} with key {self.key_id}",
                      file=sys.stderr, flush=True)
                if (over := self.gate.taken_over) is not None:
                    self.gate.taken_over = None
                    self._told = [over[0], over[1], TAKEN_OVER if over[2] else REPLACED, 0]
                    self._tell_ended()
            if reply is not None:
                self.sock.sendto(reply, addr)
            return None
        plain, why = self.gate.open(data, addr)
        if plain is not None and plain[3] == BYE:  # the host is done: the next need not wait for it
            self.end_session()
            return None
        if plain is not None:
            self.opened_from[f"{addr[0]}:{addr[1]}"] += 1
        else:
            self.refused(addr, why)
            if why == "other-address" and self._told is not None and addr == self._told[1]:
                self._tell_ended()  # (the host taken over still sends: told again, a few times at most)
            if why == "unauthenticated" and (refusal := self.gate.refuse_unauthenticated(data, addr,
                                                                                       time.monotonic())):
                self.sock.sendto(refusal, addr)  # (a host without the key is told, not left waiting)
        return plain

    def _tell_ended(self) -> None:
        """Tell the host whose session another host's took over that it has ended, and why (a BYE sealed in its own
        session, so no one else can say it): at the takeover, and again when its datagrams keep coming (``TOLD``
        times at most)."""
        session, peer, why, told = self._told
        if told >= TOLD:
            return
        self._told[3] += 1
        with contextlib.suppress(OSError):
            self.sock.sendto(session.seal(pack_bytes(BYE, self.robot_id, self.gate.next_seq(), bytes([why]),
                                                     session.id)), peer)

    def current(self, plain: bytes) -> bool:
        """An opened datagram is of the session in use (or the one its host re-keyed): not of one that has ended
        since it was opened (another host's took it over, its host said BYE) — a datagram read before the change,
        taken after it."""
        if self.gate.key is None:
            return True
        sid = SEQ.unpack_from(plain, SESSION_AT)[0]
        gate = self.gate
        return gate.session is not None and (sid == gate.session.id or gate.previous is not None
                                             and sid == gate.previous.id)

    def refused(self, addr: tuple, why: str) -> None:
        """A datagram refused: counted by reason, and written to the security log (a handshake's own repeats,
        answered as before, are no refusal)."""
        self.rx.dropped[why] += 1
        if self.log is not None and not why.endswith("-again"):
            self.log.refused(addr, why)

    def end_session(self) -> None:
        """The session ends (its host's BYE, a new key): its socket closed, nothing sent until the next."""
        self.gate.end()
        if self.session_sock is not None:
            self.session_sock.close()
            self.session_sock = None

    def reload_key(self) -> str:
        """The key file read again (SIGHUP): a rotated key ends every session made under the old one; an unusable
        file is said and the key kept (a bridge holding a robot does not stop for a bad file). What happened, in
        words."""
        from rehabkit.hardware.security.keys import KeyFileError, check_robot, load_key

        old = self.gate.key
        if old is None or old.path is None:
            return "no key to reload (the bridge was started without --key)"
        clearing = self.gate.clear_key
        try:
            key = load_key(old.path)
            check_robot(key, old.robot)
            clear_key = load_key(clearing.path) if clearing is not None and clearing.path is not None else clearing
        except KeyFileError as exc:
            return f"key kept ({old.id}): {exc}"
        if key.id == old.id and (clear_key is None or clear_key.id == clearing.id):
            return f"key {old.id} unchanged"
        self.end_session()
        self.gate.rekey(key, clear_key)
        if self.log is not None:
            self.log.note("key-reloaded", key_id=key.id, ended_key_id=old.id)
        return f"key {key.id} now (rotated); the sessions under key {old.id} ended"

    def _connect(self, addr: tuple) -> None:
        if self.session_sock is not None:
            self.session_sock.close()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.bind((self.host, self.port))
        sock.connect(addr)
        sock.setblocking(False)
        self.session_sock = sock

    def send(self, what: tuple, addr: tuple) -> None:
        """A STATE or CLOCK (``what``: kind, values, sent at, echo, status, held, measured, instruments), sealed."""
        kind, values, sent, echo, status, held, measured, instruments = what
        if self.gate.key is not None and self.gate.session is None:  # (a person's joint data goes sealed, or not)
            return
        data = encode(kind, self.robot_id, self.gate.next_seq(), values, sent, echo=echo, status=status, held=held,
                      measured=measured, instruments=instruments, link=self.gate)
        if self.session_sock is not None and addr == self.gate.peer:
            with contextlib.suppress(ConnectionRefusedError):  # the host is gone (the watchdog holds the robot)
                self.session_sock.send(data)
        else:
            self.sock.sendto(data, addr)

    def stats(self) -> dict:
        """What the link accepted and refused (by reason), and its sessions: ``rehabkit bridge --stats``."""
        gate = self.gate
        return {"key_id": gate.key.id if gate.key is not None else None,  # the bridge's own, now (after a rotation too)
                "clear_key_id": gate.clear_key.id if gate.clear_key is not None else None,
                "commands_accepted": self.rx.accepted, "dropped": dict(sorted(self.rx.dropped.items())),
                "dropped_total": sum(self.rx.dropped.values()), "sessions": self.sessions, "rekeys": self.gate.rekeys,
                "opened_from": dict(self.opened_from)}
