"""A UDP relay that impairs a host-bridge link, for fault tests (run as its own process).

    python tests/netem.py BRIDGE_PORT [--loss P] [--delay-share P] [--delay-ms A B] [--forge-every N]
                          [--cut-at-s T] [--lockstep] [--seed S]

Listens on a free port (printed as ``netem: PORT``), forwards host datagrams to the bridge
and the bridge's back to the host, dropping a share of them each way, holding a share back
by a random delay (so they arrive late and out of order), slipping forged states (wrong
robot id, then a broken checksum) to the host every N datagrams, and from ``--cut-at-s``
on dropping everything (a cut cable).

``--lockstep``: the link runs on the host's clock (``backend.clock: lockstep``). Delays and
the cut are then in the link's time, read from the host's ticks; the clock passes unimpaired
(it is the clock, not data): a held-back datagram goes on before the first clock tick at
or after its due time. A tick riding on a command or a state is split from it when the data
is dropped or held back, or when held datagrams go on first: the data as the datagram would
be without the tick, then a bare CLOCK. Every decision comes from the seeded generator in the
order the datagrams arrive, which the lock-step makes fixed: the same seed impairs a run the
same way.
"""

from __future__ import annotations

import argparse
import heapq
import socket
import time
import zlib

import numpy as np

from rehabkit.hardware.link.protocol import CLOCK, CRC, HEADER, PLAIN, STATE, TICK, encode, link_tick


def split_tick(data: bytes) -> tuple[bytes, bytes]:
    """A datagram carrying a tick as the same data without it, and the bare CLOCK it carried."""
    fields = list(HEADER.unpack_from(data))
    fields[9] &= ~TICK
    body = HEADER.pack(*fields) + data[HEADER.size : len(data) - CRC.size]
    clock = encode(CLOCK, fields[3], fields[4], np.zeros(0), fields[5])
    return body + CRC.pack(zlib.crc32(body)), clock


class Relay:
    """The impairments, decided per datagram of data in arrival order from one seeded generator."""

    def __init__(self, args: argparse.Namespace, sock: socket.socket) -> None:
        self.args, self.sock = args, sock
        self.rng = np.random.default_rng(args.seed)
        self.later: list[tuple[float, int, bytes, tuple]] = []  # (due, tie, data, destination)
        self.count = self.tie = 0

    def impair(self, data: bytes, dest: tuple, host: tuple, now: float) -> bytes | None:
        """Drop ``data``, hold it back, or return it to be sent on at once (forged states slipped in first)."""
        args = self.args
        if now >= args.cut_at_s or self.rng.random() < args.loss:
            return None
        self.count += 1
        if args.forge_every and dest == host and self.count % args.forge_every == 0:
            forged = encode(STATE, 99, 10**6 + self.count, np.full((3, args.joints), 1e3))
            self.sock.sendto(forged, host)  # a well-formed state from another robot
            self.sock.sendto(data[:-1] + bytes([data[-1] ^ 0xFF]), host)  # a corrupted copy of the real one
        if self.rng.random() < args.delay_share:
            self.tie += 1
            heapq.heappush(self.later, (now + self.rng.uniform(*args.delay_ms) / 1e3, self.tie, data, dest))
            return None
        return data

    def due(self, now: float) -> list[tuple[bytes, tuple]]:
        out = []
        while self.later and self.later[0][0] <= now:
            _, _, data, dest = heapq.heappop(self.later)
            out.append((data, dest))
        return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("bridge_port", type=int)
    ap.add_argument("--loss", type=float, default=0.0)
    ap.add_argument("--delay-share", type=float, default=0.0)
    ap.add_argument("--delay-ms", type=float, nargs=2, default=(3.0, 10.0))
    ap.add_argument("--forge-every", type=int, default=0)
    ap.add_argument("--cut-at-s", type=float, default=float("inf"))
    ap.add_argument("--lockstep", action="store_true")
    ap.add_argument("--joints", type=int, default=6)
    ap.add_argument("--robot-id", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(args.lockstep)  # lock-step: nothing is due between datagrams, so wait for the next
    relay = Relay(args, sock)
    bridge = ("127.0.0.1", args.bridge_port)
    host = None
    start = time.monotonic()
    clock = 0.0  # lock-step: the link's time, from the host's newest tick
    print(f"netem: {sock.getsockname()[1]}", flush=True)
    while True:
        now = clock if args.lockstep else time.monotonic() - start
        for held, to in relay.due(now):
            sock.sendto(held, to)
        try:
            data, addr = sock.recvfrom(65536)
        except BlockingIOError:
            time.sleep(5e-5)
            continue
        if addr[1] != args.bridge_port:
            host = addr
        dest = bridge if addr == host else host
        if dest is None:
            continue
        tick = link_tick(PLAIN.open(data)[0] or b"", args.robot_id) if args.lockstep else None  # (no key: plain)
        if tick is None:
            if (passed := relay.impair(data, dest, host, now)) is not None:
                sock.sendto(passed, dest)
            continue
        alone, clock_only = (None, data) if tick[1] else split_tick(data)
        passed = None if alone is None else relay.impair(alone, dest, host, now)
        if dest == bridge:  # the host's tick (the bridge's answers carry the time its tick ends: no news)
            clock = max(clock, tick[0])
        due = relay.due(clock)  # what is due by this tick goes first
        if passed is not None and not due:
            sock.sendto(data, dest)  # the data and its tick, as they came
            continue
        if passed is not None:
            sock.sendto(passed, dest)
        for held, to in due:
            sock.sendto(held, to)
        sock.sendto(clock_only, dest)


if __name__ == "__main__":
    main()
