"""A UDP relay that impairs a host-bridge link, for fault tests (run as its own process).

    python tests/netem.py BRIDGE_PORT [--loss P] [--delay-share P] [--delay-ms A B] [--forge-every N]
                          [--cut-at-s T] [--lockstep] [--seed S]

Listens on a free port (printed as ``netem: PORT``), forwards host datagrams to the bridge
and the bridge's back to the host, dropping a share of them each way, holding a share back
by a random delay (so they arrive late and out of order), slipping forged states (wrong
robot id, then a broken checksum) to the host every N datagrams, and from ``--cut-at-s``
on dropping everything (a cut cable).

``--lockstep``: the link runs on the host's clock (``backend.clock: lockstep``). Delays and
the cut are then in the link's time, read from the CLOCK datagrams, which pass unimpaired
(they are the clock, not data): a held-back datagram goes on before the first clock tick at
or after its due time. Every decision comes from the seeded generator in the order the
datagrams arrive, which the lock-step makes fixed: the same seed impairs a run the same way.
"""

from __future__ import annotations

import argparse
import heapq
import socket
import time

import numpy as np

from rehabkit.hardware.protocol import STATE, clock_time, encode


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
    rng = np.random.default_rng(args.seed)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(args.lockstep)  # lock-step: nothing is due between datagrams, so wait for the next
    bridge = ("127.0.0.1", args.bridge_port)
    host = None
    later: list[tuple[float, int, bytes, tuple]] = []  # (due, tie, data, destination)
    count = tie = 0
    start = time.monotonic()
    clock = 0.0  # lock-step: the link's time, from the newest CLOCK datagram
    print(f"netem: {sock.getsockname()[1]}", flush=True)
    while True:
        now = clock if args.lockstep else time.monotonic() - start
        while later and later[0][0] <= now:
            _, _, data, dest = heapq.heappop(later)
            sock.sendto(data, dest)
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
        if args.lockstep and (t := clock_time(data, args.robot_id)) is not None:
            clock = max(clock, t)
            while later and later[0][0] <= clock:  # what is due by this tick goes first
                _, _, held, to = heapq.heappop(later)
                sock.sendto(held, to)
            sock.sendto(data, dest)
            continue
        if now >= args.cut_at_s or rng.random() < args.loss:
            continue
        count += 1
        if args.forge_every and dest == host and count % args.forge_every == 0:
            forged = encode(STATE, 99, 10**6 + count, np.full((3, args.joints), 1e3))
            sock.sendto(forged, host)  # a well-formed state from another robot
            sock.sendto(data[:-1] + bytes([data[-1] ^ 0xFF]), host)  # a corrupted copy of the real one
        if rng.random() < args.delay_share:
            tie += 1
            heapq.heappush(later, (now + rng.uniform(*args.delay_ms) / 1e3, tie, data, dest))
        else:
            sock.sendto(data, dest)


if __name__ == "__main__":
    main()
