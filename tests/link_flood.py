"""A flood spoofing the host's own address at a real-time bridge, for tests/test_link_flood.py and
benchmarks/link_attacks.py: run it as root in a network namespace of its own (the flood then loads no one else's
loopback), e.g.

    unshare -n sh -c 'ip link set lo up && exec python tests/link_flood.py KEY_FILE --flood-s 0.5'

It starts ``rehabkit bridge hit --key KEY_FILE`` in real time, opens a session as the host would and drives the robot
for ``--drive-s`` (holding its start posture), then stops commanding and floods the bridge's port for ``--flood-s``
from a raw socket with datagrams whose source is the host's own address and port and whose header names the host's
session (what one captured datagram tells anyone): each reaches the session's own socket, and each costs the bridge
an authentication that fails. It prints one JSON line: the flood (datagrams sent, seconds) and the bridge's
``--stats`` (its ticks' lateness, its watchdog's holds, what it dropped).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rehabkit.hardware.link.clock import wait_readable, wait_until
from rehabkit.hardware.link.protocol import (
    CMD_RESET,
    COMMAND,
    HEADER,
    MAGIC,
    STATE,
    VERSION,
    Receiver,
    encode,
)
from rehabkit.hardware.security.handshake import handshake
from rehabkit.hardware.security.keys import load_key

Q0 = np.radians([0.0, 90.0, 90.0, 30.0, -90.0, 90.0])  # HIT's start posture (as tests/test_bridge_hold.py's)
ROOT = Path(__file__).resolve().parents[1]


def spoofed(src: tuple, dst: tuple, payload: bytes) -> bytes:
    """An IPv4 packet carrying a UDP datagram from ``src`` to ``dst`` (any source: the kernel fills the checksum;
    the UDP checksum 0 means none)."""
    udp = struct.pack("!HHHH", src[1], dst[1], 8 + len(payload), 0) + payload
    return struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), 0, 0, 64, socket.IPPROTO_UDP, 0,
                       socket.inet_aton(src[0]), socket.inet_aton(dst[0])) + udp


def flood(src: tuple, dst: tuple, session: int, seconds: float) -> int:
    """As fast as this process can send for ``seconds``: sealed-looking COMMANDs of the host's session, from its
    address, each a fresh sequence number (so each is authenticated, and fails). Datagrams sent."""
    rng = np.random.default_rng(0)
    raw = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)  # (IP_HDRINCL: the source is ours)
    pool = [spoofed(src, dst, HEADER.pack(MAGIC, VERSION, COMMAND, 1, 10**6 + i, 0.0, 0.0, 6, 0, 0, 0, 0, session)
                    + rng.bytes(6 * 8 + 16)) for i in range(4096)]
    n, until, to = 0, time.monotonic() + seconds, (dst[0], 0)
    while time.monotonic() < until:
        for packet in pool:
            try:  # noqa: SIM105 (the fastest loop: no context manager per datagram)
                raw.sendto(packet, to)
            except OSError:  # (a full buffer: go on)
                pass
        n += len(pool)
    return n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("key")
    ap.add_argument("--drive-s", type=float, default=0.2)
    ap.add_argument("--flood-s", type=float, default=0.5)
    ap.add_argument("--watchdog-ms", type=float, default=50.0)
    args = ap.parse_args()
    stats = Path(tempfile.mkdtemp()) / "bridge.json"
    bridge = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", args.key, "--stats",
                               str(stats), "--watchdog-ms", str(args.watchdog_ms)], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    try:
        port = int(bridge.stdout.readline().rsplit(":", 1)[1])
        addr = ("127.0.0.1", port)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        seq = iter(range(1, 1 << 31))
        session = handshake(sock, addr, load_key(args.key), 1, lambda: next(seq))
        rx = Receiver(STATE, 1, 6, link=session)
        sock.sendto(encode(COMMAND, 1, next(seq), Q0, status=CMD_RESET, link=session), addr)
        hold = None
        while hold is None and wait_readable(sock, 2.0):
            msg = rx.accept(sock.recv(65536))
            hold = None if msg is None else msg.values[2]  # the torque holding the start posture (≈ gravity's)
        deadline = time.monotonic()
        q, qd = Q0, np.zeros(6)
        for _ in range(int(args.drive_s * 1000)):  # the host's 1 kHz: hold the start posture by torque
            sock.sendto(encode(COMMAND, 1, next(seq), hold + 60 * (Q0 - q) - 6 * qd, link=session), addr)
            deadline += 1e-3
            wait_until(deadline)
            while True:
                try:
                    msg = rx.accept(sock.recv(65536))
                except BlockingIOError:
                    break
                if msg is not None:
                    q, qd = msg.values[0], msg.values[1]
        t0 = time.monotonic()
        sent = flood(sock.getsockname(), addr, session.id, args.flood_s)  # and the host says no more
        seconds = time.monotonic() - t0
    finally:
        bridge.send_signal(signal.SIGINT)
        bridge.wait(10)
        bridge.stdout.close()
    report = json.loads(stats.read_text())
    os.unlink(stats)
    print(json.dumps({"sent": sent, "seconds": seconds, "session": f"{session.id:08x}", "bridge": report}))


if __name__ == "__main__":
    main()
