"""An attacker on the robot link, for tests/test_link_attacks.py and benchmarks/link_attacks.py (a process of its own).

    python tests/link_attacker.py BRIDGE_PORT --joints N [--robot-id 1] [--count N] [--flood-s S] [--after N]
                                  [--earlier CAPTURE] [--save CAPTURE] [--report REPORT.json] [--seed S]
                                  [--attacks forged,replayed,tampered,wrong-key,flood] [--key KEY_FILE]

It sits on the path between host and bridge (the host is pointed at the port it prints, ``attacker: PORT``) and
forwards every datagram unchanged both ways, keeping a copy: what a machine on the lab's network can capture.
Once the run is under way (``--after`` host datagrams relayed in the host's ``--session``-th session; the sessions
before it are only captured, earlier sessions to replay) it attacks from a socket of its own, in turn, each
attack ``--count`` datagrams (the flood: ``--flood-s`` seconds):

  forged     well-formed, CRC-valid datagrams without the key: torque commands, resets, CLEARs with a name,
             lock-step CLOCKs ahead of time to the bridge, states with 1000-rad joints to the host
  replayed   datagrams captured from this session (to where they went) and from an earlier one (``--earlier``)
  tampered   captured datagrams with one bit flipped
  wrong-key  HELLOs with a MAC1 it cannot make, this session's and an earlier session's PROOF and HELLO again
  flood      as fast as one process can send, to the bridge's port: random bytes, replays, HELLOs (from a
             process of its own, while the others go on)
  wrong-proof  what a stranger can do to the handshake now that it gets no challenge (benchmarks/link_attacks.py):
             as fast as one process can send, to the bridge's port, PROOFs with wrong MACs (naming the host's
             captured HELLOs, and random ones) and HELLOs with a wrong MAC1 (a process of its own, as the flood)
  takeover   a holder of the robot's key (``--key``) takes the live session over (benchmarks/link_attacks.py): a
             handshake of its own from another port, then ``rehabkit estop clear --bridge ... --key`` as the README
             gives it; the outcome of each in the report

It says ``attacker: done`` when through; on SIGTERM it writes the report (datagrams sent and answers received
per attack) and the capture (``--save``).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import signal
import socket
import struct
import threading
import time
from pathlib import Path

import numpy as np

from rehabkit.hardware.link.protocol import (
    CLEAR,
    CLOCK,
    CMD_RESET,
    COMMAND,
    HEADER,
    PLAIN,
    STATE,
    encode,
    pack_bytes,
)
from rehabkit.hardware.security.handshake import CHALLENGE, HELLO, PROOF, peek_kind

RECORD = struct.Struct("<BH")  # direction (0: host → bridge, 1: bridge → host), length


def save(path: str, capture: list[tuple[int, bytes]]) -> None:
    with open(path, "wb") as f:
        for way, data in capture:
            f.write(RECORD.pack(way, len(data)) + data)


def load(path: str | None) -> list[tuple[int, bytes]]:
    if not path or not os.path.exists(path):
        return []
    raw, out, at = Path(path).read_bytes(), [], 0
    while at < len(raw):
        way, n = RECORD.unpack_from(raw, at)
        out.append((way, raw[at + RECORD.size : at + RECORD.size + n]))
        at += RECORD.size + n
    return out


def flip(data: bytes, rng: np.random.Generator) -> bytes:
    """``data`` with one random bit flipped."""
    bit = int(rng.integers(8 * len(data)))
    flipped = bytearray(data)
    flipped[bit // 8] ^= 1 << bit % 8
    return bytes(flipped)


def _send_all(sock: socket.socket, to: tuple, pool: list[bytes], seconds: float) -> int:
    """``pool`` sent over and over to ``to`` as fast as it goes for ``seconds``; how many were sent."""
    n, until = 0, time.monotonic() + seconds
    while time.monotonic() < until:
        for data in pool:
            try:  # noqa: SIM105 (the fastest loop: no context manager per datagram)
                sock.sendto(data, to)
            except OSError:  # (a full send buffer: go on)
                pass
        n += len(pool)
    return n


def flood_bridge(bridge: tuple, seconds: float, samples: list[bytes], hello: bytes, seed: int, sent) -> None:
    """As fast as it can for ``seconds``: random bytes, replays, HELLOs (a process of its own)."""
    rng = np.random.default_rng(seed)
    junk = [bytes(rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8)) for _ in range(256)]
    pool = junk + samples[:256] + [hello] * 16
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent.value = _send_all(sock, bridge, pool, seconds)


def flood_handshakes(bridge: tuple, seconds: float, ehs: list[bytes], rid: int, seed: int, sent, answers) -> None:
    """As fast as it can for ``seconds``: PROOFs with wrong MACs (naming the HELLOs' ``ehs``, and random ones) and
    HELLOs with a wrong MAC1, to the bridge's port (a process of its own); the answers it got counted at the end."""
    rng = np.random.default_rng(seed)
    pool = []
    for i in range(512):
        eh = ehs[i % len(ehs)] if ehs and i % 2 else rng.bytes(32)
        pool.append(PLAIN.seal(pack_bytes(PROOF, rid, 2 * i + 1, eh + rng.bytes(32))))
        pool.append(PLAIN.seal(pack_bytes(HELLO, rid, 2 * i + 2, rng.bytes(32) + bytes(16) + rng.bytes(16))))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    sent.value = _send_all(sock, bridge, pool, seconds)
    time.sleep(0.05)
    while True:  # (refusals: at most 5 a second to a source; its socket's buffer holds them all)
        try:
            sock.recv(65536)
        except (BlockingIOError, ConnectionRefusedError):
            break
        answers.value += 1


class CountingSocket(socket.socket):
    """A UDP socket that counts what it sent and what came to it (for the takeover's handshake)."""

    def __init__(self):
        super().__init__(socket.AF_INET, socket.SOCK_DGRAM)
        self.setblocking(False)
        self.sent = self.came = 0

    def sendto(self, data: bytes, to: tuple) -> int:
        self.sent += 1
        return super().sendto(data, to)

    def recvfrom(self, n: int) -> tuple[bytes, tuple]:
        got = super().recvfrom(n)
        self.came += 1
        return got


class Attacker:
    def __init__(self, args: argparse.Namespace):
        self.args, self.bridge = args, ("127.0.0.1", args.bridge_port)
        self.rng = np.random.default_rng(args.seed)
        self.host: tuple | None = None
        self.capture: list[tuple[int, bytes]] = []
        self.earlier = load(args.earlier)
        self.report: dict[str, dict[str, int]] = {}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # the attacker's own (not the relay's)
        self.sock.setblocking(False)
        self.challenges: list[bytes] = []
        self.in_flight = 0  # datagrams still to tamper with in flight
        self.hellos, self.since_hello = 0, 0  # the host's sessions relayed (a new run: a new port), its datagrams since
        self.relayed = threading.Condition()  # the relay's thread says so each time it has passed one on

    def forward(self, data: bytes) -> bytes:
        """What the relay passes on: ``data``, or (while tampering in flight, one in ten) with a bit flipped."""
        if self.in_flight > 0 and self.rng.random() < 0.1:
            self.in_flight -= 1
            self.report.setdefault("tampered in flight", {"sent": 0})["sent"] += 1
            return flip(data, self.rng)
        return data

    def send(self, attack: str, data: bytes, to: tuple) -> None:
        self.sock.sendto(data, to)
        self.report.setdefault(attack, {"sent": 0})["sent"] += 1
        self._drain(attack)

    def _drain(self, attack: str) -> None:
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            kind = peek_kind(data)
            self.report[attack]["answers"] = self.report[attack].get("answers", 0) + 1
            if kind == CHALLENGE:
                self.challenges.append(data)

    def run(self) -> None:
        a, n, j, rid = self.args, self.args.count, self.args.joints, self.args.robot_id
        if n == 0:  # only on the path, capturing (an earlier session for the next run to replay)
            return
        with self.relayed:
            self.relayed.wait_for(lambda: self.hellos >= a.session and self.since_hello >= a.after
                                  and self.host is not None)
        rng, attacks = self.rng, set(a.attacks.split(","))
        flood = None
        if a.flood_s > 0 and "flood" in attacks:  # from a process of its own, while the others go on
            hellos = [d for w, d in self.capture if w == 0 and peek_kind(d) == HELLO]
            sent = multiprocessing.get_context("fork").Value("q", 0)
            samples = [d for _, d in self.capture[-256:]]
            flood = multiprocessing.get_context("fork").Process(
                target=flood_bridge, args=(self.bridge, a.flood_s, samples, hellos[0] if hellos else b"", a.seed, sent))
            start = time.time()
            flood.start()
        if a.flood_s > 0 and "wrong-proof" in attacks:  # a stranger's flood at the handshake, while the run goes on
            ehs = [d[HEADER.size:HEADER.size + 32] for w, d in self.capture if w == 0 and peek_kind(d) == HELLO]
            context = multiprocessing.get_context("fork")
            sent, answers = context.Value("q", 0), context.Value("q", 0)
            flood = context.Process(target=flood_handshakes, args=(self.bridge, a.flood_s, ehs, rid, a.seed, sent,
                                                                   answers))
            start = time.time()
            flood.start()
        if "takeover" in attacks:
            self.take_over()
        for i in range(n if "forged" in attacks else 0):  # forged, without the key
            seq = 10**6 + i
            self.send("forged", encode(COMMAND, rid, seq, rng.uniform(-50, 50, j)), self.bridge)
            self.send("forged", encode(COMMAND, rid, seq + 1, rng.uniform(-1, 1, j), status=CMD_RESET), self.bridge)
            self.send("forged", PLAIN.seal(pack_bytes(CLEAR, rid, seq + 2, b"mallory")), self.bridge)
            self.send("forged", encode(CLOCK, rid, seq + 3, np.zeros(0), 1e3 + i), self.bridge)
            self.send("forged", encode(STATE, rid, seq + 4, np.full((3, j), 1e3)), self.host)
        now = list(self.capture)
        # replayed: this session's (the newest, inside the window, and older) and an earlier one's
        for i in range(n if "replayed" in attacks else 0):
            way, data = now[-1 - int(rng.integers(0, min(len(now), 64)))] if i % 2 else now[int(rng.integers(len(now)))]
            self.send("replayed", data, self.bridge if way == 0 else self.host)
            if self.earlier:
                way, data = self.earlier[int(rng.integers(len(self.earlier)))]
                self.send("replayed", data, self.bridge if way == 0 else self.host)
        for _ in range(n if "tampered" in attacks else 0):  # tampered: one bit flipped in a captured datagram
            way, data = self.capture[-1 - int(rng.integers(0, min(len(self.capture), 256)))]
            self.send("tampered", flip(data, rng), self.bridge if way == 0 else self.host)
        # and in flight: the relay flips a bit in one in ten it forwards, instead of forwarding it
        self.in_flight = min(n // 4, 100) if "tampered" in attacks else 0
        with self.relayed:
            self.relayed.wait_for(lambda: self.in_flight == 0)
        hellos = [d for w, d in self.capture + self.earlier if w == 0 and peek_kind(d) == HELLO]
        proofs = [d for w, d in self.capture + self.earlier if w == 0 and peek_kind(d) == PROOF]
        for i in range(n if "wrong-key" in attacks else 0):  # wrong key
            hello = bytes(rng.integers(0, 256, 64, dtype=np.uint8))  # (a key, padding, a MAC1 it cannot make)
            self.send("wrong-key", PLAIN.seal(pack_bytes(HELLO, rid, 2 * i + 1, hello)), self.bridge)
            if hellos:  # the host's own, again (its challenge was proven: a replay)
                self.send("wrong-key", hellos[i % len(hellos)], self.bridge)
            for challenge in self.challenges[-4:]:  # (a challenge it was given: none, without a MAC1)
                proof = challenge[-(32 + 32 + 4):-4 - 32] + bytes(rng.integers(0, 256, 32, dtype=np.uint8))
                self.send("wrong-key", PLAIN.seal(pack_bytes(PROOF, rid, 2 * i + 2, proof)), self.bridge)
            self.challenges.clear()
            for proof in proofs:
                self.send("wrong-key", proof, self.bridge)
            time.sleep(0.001)  # (the bridge answers each source 5 times a second outside a session)
        if flood is not None:
            flood.join()
            self.report["flood"] = {"sent": int(sent.value), "seconds": a.flood_s, "from": start, "to": time.time()}
            if "wrong-proof" in attacks:
                self.report["flood"]["answers"] = int(answers.value)
        self.report["done"] = {"at": time.time()}
        print("attacker: done", flush=True)

    def take_over(self) -> None:
        """A key holder's handshake from a port of its own while the session is live, then the README's
        ``rehabkit estop clear --bridge ... --key`` (each given 2 s): what each achieved."""
        import subprocess
        import sys

        from rehabkit.hardware.security.handshake import LinkRefusedError, handshake
        from rehabkit.hardware.security.keys import load_key

        a = self.args
        key = load_key(a.key)
        sock, seq = CountingSocket(), iter(range(1, 1 << 31))
        t0 = time.monotonic()
        try:
            session = handshake(sock, self.bridge, key, a.robot_id, lambda: next(seq), timeout=2.0)
            got = f"session {session.id:08x}"
        except LinkRefusedError as exc:
            got = f"refused: {exc.reason}"
        except TimeoutError:
            got = "no answer"
        self.report["takeover"] = {"sent": sock.sent, "answers": sock.came, "handshake": got,
                                   "s": round(time.monotonic() - t0, 2)}
        t0 = time.monotonic()
        done = subprocess.run([sys.executable, "-m", "rehabkit.cli", "estop", "clear", f"{key.robot}", "--by",
                               "mallory", "--bridge", f"{self.bridge[0]}:{self.bridge[1]}", "--key", a.key],
                              capture_output=True, text=True, timeout=60)
        said = (done.stderr.strip() or done.stdout.strip()).splitlines()
        self.report["takeover"].update({"estop_clear_exit": done.returncode, "estop_clear_said": said[-1] if said
                                        else "", "estop_clear_s": round(time.monotonic() - t0, 2)})
        sock.close()

    def finish(self) -> None:
        if self.args.save:
            save(self.args.save, self.capture)
        if self.args.report:
            tmp = self.args.report + ".tmp"
            with open(tmp, "w") as f:
                json.dump({**self.report, "captured": len(self.capture)}, f, indent=1)
            os.replace(tmp, self.args.report)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("bridge_port", type=int)
    p.add_argument("--joints", type=int, required=True)
    p.add_argument("--robot-id", type=int, default=1)
    p.add_argument("--count", type=int, default=200)
    p.add_argument("--flood-s", type=float, default=1.0)
    p.add_argument("--after", type=int, default=300, help="host datagrams relayed before the attacks begin")
    p.add_argument("--session", type=int, default=1, help="in the host's session this one (sessions before it are "
                   "captured: earlier sessions to replay)")
    p.add_argument("--earlier", default=None)
    p.add_argument("--save", default=None)
    p.add_argument("--report", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--attacks", default="forged,replayed,tampered,wrong-key,flood", help="which, comma-separated")
    p.add_argument("--key", default=None, help="the robot's key file (a key holder's takeover)")
    args = p.parse_args()
    attacker = Attacker(args)
    relay = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    relay.bind(("127.0.0.1", 0))
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(0)))
    print(f"attacker: {relay.getsockname()[1]}", flush=True)
    def attack() -> None:
        try:
            attacker.run()
        except Exception as exc:  # noqa: BLE001 (said in the report, and the relay ends: no silent hang)
            attacker.report["failed"] = {"error": repr(exc)}
            print(f"attacker: done (failed: {exc!r})", flush=True)

    threading.Thread(target=attack, daemon=True).start()
    try:
        while True:
            data, addr = relay.recvfrom(65536)
            # forwarded first, then kept: a replay never overtakes the datagram it copies
            if addr == attacker.bridge:
                if attacker.host is not None:
                    relay.sendto(attacker.forward(data), attacker.host)
                attacker.capture.append((1, data))
            else:
                # (a new run is a new socket: its port; a HELLO from the same one re-keys its session)
                attacker.hellos, attacker.since_hello = (attacker.hellos + 1, 0) if addr != attacker.host else \
                    (attacker.hellos, attacker.since_hello + 1)
                attacker.host = addr
                relay.sendto(attacker.forward(data), attacker.bridge)
                attacker.capture.append((0, data))
            with attacker.relayed:
                attacker.relayed.notify_all()
    finally:
        attacker.finish()


if __name__ == "__main__":
    main()
