"""A flood spoofing the host's own address at a real-time bridge, for tests/test_link_flood.py and
benchmarks/link_attacks.py: run it as root in a network namespace of its own (the flood then loads no one else's
loopback), e.g.

    unshare -n sh -c 'ip link set lo up && exec python tests/link_flood.py KEY_FILE --flood-s 0.5'

It starts ``rehabkit bridge hit --key KEY_FILE`` in real time, opens a session as the host would and drives the robot
for ``--drive-s`` (holding its start posture), then stops commanding and floods the bridge's port for ``--flood-s``
from a raw socket with datagrams whose source is the host's own address and port and whose header names the host's
session (what one captured datagram tells anyone): each reaches the session's own socket, and each costs the bridge
an authentication that fails. It prints one JSON line: the flood (datagrams sent, seconds), the bridge's ``--stats``
(its ticks' lateness, its watchdog's holds, what it dropped) and the posture as the bridge's states told the host
(``deviation_deg``: the largest joint deviation from the start posture while driving and during the flood).
``--silent`` sends nothing instead of the flood (the same run unflooded, for comparison).

``--attack refused`` (benchmarks/link_attacks.py) forges REFUSEDs instead: the host opens ``--tries`` sessions, one
after the other, and a forger watching loopback (a packet socket: an observer on the path) answers each HELLO at once
with a burst of REFUSEDs, in turn from another address (127.0.0.2) or spoofed as the bridge's own, naming the HELLO
(as only an observer can) or not (blind). It prints one JSON line: per way, the handshakes made and aborted.
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
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from rehabkit.hardware.link.clock import wait_readable, wait_until
from rehabkit.hardware.link.protocol import (
    CMD_RESET,
    COMMAND,
    HEADER,
    MAGIC,
    PLAIN,
    STATE,
    VERSION,
    Receiver,
    encode,
    pack_bytes,
)
from rehabkit.hardware.security.handshake import BYE, HELLO, NO_KEY, REFUSED, LinkRefusedError, handshake, peek_kind
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


def _waiting(sock: socket.socket, rx) -> Iterator:
    """The messages waiting in ``sock`` (not blocking) that ``rx`` accepts."""
    while True:
        try:
            msg = rx.accept(sock.recv(65536))
        except BlockingIOError:
            return
        if msg is not None:
            yield msg


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("key")
    ap.add_argument("--drive-s", type=float, default=0.2)
    ap.add_argument("--flood-s", type=float, default=0.5)
    ap.add_argument("--watchdog-ms", type=float, default=50.0)
    ap.add_argument("--silent", action="store_true", help="send nothing instead of the flood (the unflooded run)")
    ap.add_argument("--attack", choices=("spoofed-flood", "refused"), default="spoofed-flood")
    ap.add_argument("--tries", type=int, default=5, help="--attack refused: handshakes for each way of forging")
    args = ap.parse_args()
    stats = Path(tempfile.mkdtemp()) / "bridge.json"
    bridge = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", args.key, "--stats",
                               str(stats), "--watchdog-ms", str(args.watchdog_ms)], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    deviation = {}
    try:
        if args.attack == "refused":
            port = int(bridge.stdout.readline().rsplit(":", 1)[1])
            outcome = forged_refused(("127.0.0.1", port), load_key(args.key), args.tries)
            print(json.dumps(outcome))
            return
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
        driving = 0.0
        for _ in range(int(args.drive_s * 1000)):  # the host's 1 kHz: hold the start posture by torque
            sock.sendto(encode(COMMAND, 1, next(seq), hold + 60 * (Q0 - q) - 6 * qd, link=session), addr)
            deadline += 1e-3
            wait_until(deadline)
            for msg in _waiting(sock, rx):
                q, qd = msg.values[0], msg.values[1]
                driving = max(driving, float(np.degrees(np.abs(q - Q0)).max()))
        # (the states the bridge sends meanwhile wait in the host's socket, read after the flood: room for them all)
        sock.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_RCVBUFFORCE", 33), 1 << 23)
        t0 = time.monotonic()
        if args.silent:  # the host says no more, and nothing else comes
            sent = 0
            wait_until(t0 + args.flood_s)
        else:
            sent = flood(sock.getsockname(), addr, session.id, args.flood_s)  # and the host says no more
        seconds = time.monotonic() - t0
        during, states = 0.0, 0
        for msg in _waiting(sock, rx):
            states += 1
            during = max(during, float(np.degrees(np.abs(msg.values[0] - Q0)).max()))
        deviation = {"driving": driving, "flood": during, "states_during_flood": states}
    finally:
        bridge.send_signal(signal.SIGINT)
        bridge.wait(10)
        bridge.stdout.close()
    report = json.loads(stats.read_text())
    os.unlink(stats)
    print(json.dumps({"sent": sent, "seconds": seconds, "session": f"{session.id:08x}", "bridge": report,
                      "deviation_deg": deviation}))


FORGERIES = {"from elsewhere, blind": (False, False), "from elsewhere, naming the HELLO": (False, True),
             "as the bridge, blind": (True, False), "as the bridge, naming the HELLO": (True, True)}


def forged_refused(bridge: tuple, key, tries: int, burst: int = 16) -> dict:
    """``tries`` handshakes with the bridge for each way of forging a REFUSED (:data:`FORGERIES`: spoofed as the
    bridge's address or from 127.0.0.2; naming the HELLO, as an observer on the path can, or blind), each HELLO seen
    on loopback answered at once by ``burst`` of them. Per way: made, aborted (the host took a forged REFUSED), timed
    out, and the handshakes' times."""
    sniff = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(0x0003))  # (every frame on lo)
    sniff.bind(("lo", 0))
    sniff.settimeout(0.2)
    elsewhere = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    elsewhere.bind(("127.0.0.2", 0))
    raw = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)
    rng = np.random.default_rng(1)
    way = {"now": None}
    forged = {name: 0 for name in FORGERIES}
    stop = threading.Event()

    def forger() -> None:
        while not stop.is_set():
            try:
                frame = sniff.recv(65536)
            except TimeoutError:
                continue
            ip = frame[14:]
            if len(ip) < 28 or ip[9] != socket.IPPROTO_UDP:
                continue
            at = (ip[0] & 15) * 4
            sport, dport = struct.unpack_from("!HH", ip, at)
            data = ip[at + 8:]
            if dport != bridge[1] or peek_kind(data) != HELLO or way["now"] is None:
                continue
            host = (socket.inet_ntoa(ip[12:16]), sport)
            spoof, naming = FORGERIES[way["now"]]
            for _ in range(burst):
                eh = data[HEADER.size:HEADER.size + 8] if naming else rng.bytes(8)
                refusal = PLAIN.seal(pack_bytes(REFUSED, 1, 1, bytes([NO_KEY]) + eh))
                if spoof:
                    raw.sendto(spoofed(bridge, host, refusal), (host[0], 0))
                else:
                    elsewhere.sendto(refusal, host)
                forged[way["now"]] += 1

    watching = threading.Thread(target=forger, daemon=True)
    watching.start()
    out = {}
    try:
        for name in FORGERIES:
            way["now"] = name
            got = {"made": 0, "aborted": 0, "timed_out": 0, "ms": [], "said": ""}
            for _ in range(tries):
                sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                sock.bind(("127.0.0.1", 0))
                sock.setblocking(False)
                seq = iter(range(1, 1 << 31))
                t0 = time.monotonic()
                try:
                    session = handshake(sock, bridge, key, 1, lambda seq=seq: next(seq), timeout=2.0)
                    got["made"] += 1
                    got["ms"].append(round(1e3 * (time.monotonic() - t0), 2))
                    sock.sendto(session.seal(pack_bytes(BYE, 1, next(seq), b"", session.id)), bridge)
                except LinkRefusedError as exc:
                    got["aborted"] += 1
                    got["said"] = str(exc)
                except TimeoutError:
                    got["timed_out"] += 1
                sock.close()
                time.sleep(0.05)  # (the bridge reads the BYE: the next host need not wait)
            out[name] = {**got, "forged_sent": forged[name]}
    finally:
        stop.set()
        watching.join()
    return out


if __name__ == "__main__":
    main()
