"""The bridge's end of the robot link: its UDP sockets, the gate that answers handshakes and opens datagrams
(:class:`~rehabkit.hardware.security.handshake.BridgeGate`), the command receiver, and the count of all it refused.

An authenticated session gets a socket of its own, on the same port and connected to the host that proved it: the
kernel hands the host's datagrams to it and everything else to the open socket, so a flood from elsewhere queues
apart from the session's and cannot crowd its datagrams out of one buffer. The bridge reads the session's first,
and at most ``OPEN_PER_TICK`` from the open socket a tick.
"""

from __future__ import annotations

import contextlib
import socket
import sys
import time
from collections import Counter

from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.protocol import CMD_RESET, COMMAND, Receiver, encode
from rehabkit.hardware.security.handshake import HANDSHAKE, BridgeGate, peek_kind
from rehabkit.hardware.security.keys import LinkKey

OPEN_PER_TICK = 64  # datagrams read from the open socket (handshakes, strangers) at most, per tick


class BridgeLink:
    """Where the bridge listens (``host``, ``port``; 0: any free port), for ``robot_id`` with ``joints`` commanded
    joints; given ``key``, in authenticated sessions only."""

    def __init__(self, robot_id: int, joints: int, host: str = "127.0.0.1", port: int = 0,
                 key: LinkKey | None = None):
        self.robot_id = robot_id
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)  # (the session's socket shares the port)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.host, self.port = host, self.sock.getsockname()[1]
        self.session_sock: socket.socket | None = None  # connected to the proven host
        # with a key a proven handshake opens a session; without, a host's reset does (a new run, a new host
        # process, numbers its commands from 1 again)
        self.gate = BridgeGate(key, robot_id)
        self.rx = Receiver(COMMAND, robot_id, joints, restart=0 if key is not None else CMD_RESET)
        self.sessions: list[dict] = []  # each authenticated session: when, from where, its id and key id
        self.opened_from: Counter = Counter()  # datagrams let in, by the address they came from

    @property
    def key_id(self) -> str:
        """The key of the session in use, as the safety log and the latch file record it."""
        return self.gate.session.key_id if self.gate.session is not None else "none (a link without a key)"

    def arrived(self) -> list[tuple[bytes, tuple]]:
        """What came since the last tick, opened (handshakes answered, the rest refused and counted): all the
        session's, then at most ``OPEN_PER_TICK`` from the open socket."""
        out = []
        for sock, most in ((self.session_sock, None), (self.sock, OPEN_PER_TICK)):
            while sock is not None and (most is None or most > 0):
                try:
                    data, addr = sock.recvfrom(65536)
                except BlockingIOError:
                    break
                except ConnectionRefusedError:  # (the session's host is gone: its socket says so, once)
                    continue
                most = None if most is None else most - 1
                if (plain := self.open(data, addr)) is not None:
                    out.append((plain, addr))
        return out

    def next(self, timeout: float) -> tuple[bytes, tuple] | None:
        """The next datagram to come (the session's first), waiting up to ``timeout``; None if none came."""
        socks = [self.sock] if self.session_sock is None else [self.session_sock, self.sock]
        if not wait_readable(socks, timeout):
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

    def open(self, data: bytes, addr: tuple) -> bytes | None:
        """A datagram's header and body if it is one to read (intact; with a key, authentic and not seen before);
        a handshake is answered here, at once; what is refused is counted by reason."""
        if peek_kind(data) in HANDSHAKE:
            was = self.gate.session
            reply, why = self.gate.reply(data, addr)
            if why:
                self.rx.dropped[f"handshake-{why}"] += 1
            if self.gate.session is not was:  # a new session, proven: its numbers start afresh, its socket its own
                self.rx.last_seq = None
                self._connect(addr)
                self.sessions.append({"at": time.time(), "from": f"{addr[0]}:{addr[1]}",
                                      "session": f"{self.gate.id:08x}", "key_id": self.key_id})
                print(f"bridge: session {self.gate.id:08x} from {addr[0]}:{addr[1]} with key {self.key_id}",
                      file=sys.stderr, flush=True)
            if reply is not None:
                self.sock.sendto(reply, addr)
            return None
        plain, why = self.gate.open(data, addr)
        if plain is not None:
            self.opened_from[f"{addr[0]}:{addr[1]}"] += 1
        else:
            self.rx.dropped[why] += 1
            if why == "unauthenticated" and (refusal := self.gate.refuse_unauthenticated(time.monotonic())):
                self.sock.sendto(refusal, addr)  # (a host without the key is told, not left waiting)
        return plain

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
        data = encode(kind, self.robot_id, self.gate.next_seq(), values, sent, echo=echo, status=status, held=held,
                      measured=measured, instruments=instruments, link=self.gate)
        if self.session_sock is not None and addr == self.gate.peer:
            with contextlib.suppress(ConnectionRefusedError):  # the host is gone (the watchdog holds the robot)
                self.session_sock.send(data)
        else:
            self.sock.sendto(data, addr)

    def stats(self) -> dict:
        """What the link accepted and refused (by reason), and its sessions: ``rehabkit bridge --stats``."""
        return {"commands_accepted": self.rx.accepted, "dropped": dict(sorted(self.rx.dropped.items())),
                "dropped_total": sum(self.rx.dropped.values()), "sessions": self.sessions,
                "opened_from": dict(self.opened_from)}
