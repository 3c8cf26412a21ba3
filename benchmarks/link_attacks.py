"""The robot link attacked on this machine: the HIT round trip over an authenticated link, with a second process on
the path (tests/link_attacker.py) attacking in one way per row; then the decoder and the handshake fuzzed.

Each row: a fresh bridge (lock-step, with the robot's key; real time in the last rows), the attacker between it and
the host, one HIT round trip. Printed: datagrams the attacker sent (and answers it got: refusals, at most 5 a second
to each of its sources), datagrams the bridge let in from anywhere but the host (accepted), what the bridge and the
host dropped, by reason (beyond the unattacked run's), the largest joint deviation from the unattacked run, safety
events, and the run's wall time. The first row is the unattacked run through the same relay (it is also the
earlier session the others replay).

    python benchmarks/link_attacks.py [--count 2000] [--flood-s 5] [--fuzz 100000]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rehabkit.api import run_scenario
from rehabkit.hardware.security.keys import new_key

ROOT = Path(__file__).resolve().parents[1]
HIT = ROOT / "scenarios" / "hit_roundtrip.yaml"


def _start(cmd: list[str], prefix: str) -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    line = proc.stdout.readline()
    assert line.startswith(prefix), line
    return proc, int(line.rsplit(":", 1)[1])


def _stop(proc: subprocess.Popen, sig: int) -> None:
    proc.send_signal(sig)
    proc.wait(30)
    proc.stdout.close()


def attacked_run(tmp: Path, key, attacks: str, count: int, flood_s: float, realtime: bool = False):
    """One HIT round trip with the attacker on the path; the run, the bridge's stats, the attacker's report."""
    stats, report = tmp / "bridge.json", tmp / "attack.json"
    bridge, port = _start([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", str(key.path), "--stats",
                           str(stats), *(() if realtime else ("--lockstep",)), "--watchdog-ms", "200"], "bridge:")
    try:
        attacker, port = _start([sys.executable, str(ROOT / "tests" / "link_attacker.py"), str(port), "--joints", "6",
                                 "--count", str(count), "--flood-s", str(flood_s), "--attacks", attacks or "none",
                                 "--earlier", str(tmp / "capture"), "--save", str(tmp / "capture"),
                                 "--report", str(report)], "attacker:")
        try:
            backend = {"type": "hardware", "spawn_bridge": False, "port": port, "key_file": str(key.path)}
            backend.update({"bridge_watchdog_ms": 200, "state_timeout_s": 0.5} if realtime else {"clock": "lockstep"})
            t0 = time.time()
            run = run_scenario(HIT, {"backend": backend})
            span = (t0, time.time())
            if attacks:  # (its attacks through, the flood's count in: its report is written when it stops)
                assert attacker.stdout.readline().startswith("attacker: done")
        finally:
            _stop(attacker, signal.SIGTERM)
    finally:
        _stop(bridge, signal.SIGINT)
    return run, json.loads(stats.read_text()), json.loads(report.read_text()), span


def _drops(counts: dict, base: dict) -> str:
    new = {k: v - base.get(k, 0) for k, v in counts.items() if v - base.get(k, 0) > 0}
    return ", ".join(f"{k} {v}" for k, v in sorted(new.items(), key=lambda kv: -kv[1])) or "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=2000, help="datagrams per kind of each attack")
    ap.add_argument("--flood-s", type=float, default=5.0)
    ap.add_argument("--fuzz", type=int, default=100_000, help="inputs fuzzed (0: none)")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}\n")
    rows = [("none", "", False), ("forged", "forged", False), ("replayed", "replayed", False),
            ("tampered", "tampered", False), ("wrong key", "wrong-key", False), ("flood", "flood", False),
            ("all of them", "forged,replayed,tampered,wrong-key,flood", False),
            ("none, real time", "", True), ("flood, real time", "flood", True)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        key = new_key("hit-1", tmp / "hit-1.key")
        clean = {}
        print(f"{'attack':17s} {'sent':>7s} {'answers':>7s} {'accepted':>8s} {'max dev':>9s} {'events':>6s} "
              f"{'wall':>6s}  dropped at the bridge | at the host")
        for label, attacks, realtime in rows:
            run, stats, report, span = attacked_run(tmp, key, attacks, args.count, args.flood_s, realtime)
            if not attacks:
                clean[realtime] = (run, stats)
            base_run, base_stats = clean[realtime]
            sent = sum(v["sent"] for k, v in report.items() if isinstance(v, dict) and "sent" in v)
            answers = sum(v.get("answers", 0) for v in report.values() if isinstance(v, dict))
            host_at = stats["sessions"][0]["from"]
            accepted = sum(n for at, n in stats["opened_from"].items() if at != host_at)
            n = min(len(run.trace.q), len(base_run.trace.q))
            dev = np.degrees(np.abs(run.trace.q[:n] - base_run.trace.q[:n]).max())
            host = {k.removeprefix("states_dropped_"): v for k, v in run.metrics.items()
                    if k.startswith("states_dropped_")}
            base_host = {k.removeprefix("states_dropped_"): v for k, v in base_run.metrics.items()
                         if k.startswith("states_dropped_")}
            flood = report.get("flood")
            ends = min(flood["to"], flood["from"] + flood["seconds"], span[1]) if flood else 0.0
            during = max(0.0, ends - max(flood["from"], span[0])) if flood else 0.0
            overlap = f" (flood {flood['sent']} in {flood['seconds']:g} s, {during:.1f} s of it during the run)" \
                if flood else ""
            extra = ""
            if realtime:
                m = run.metrics
                extra = (f" late ticks {m['deadline_misses']:.0f}, lateness p99 {m['tick_lateness_p99_ms']:.2f} ms, "
                         f"bridge holds {m['bridge_stale_holds']:.0f}")
            events = len(run.summary["safety"]["events"])
            bridge_drops = _drops(stats["dropped"], base_stats["dropped"] if attacks else {})
            print(f"{label:17s} {sent:7d} {answers:7d} {accepted:8d} {dev:7.2g}° {events:6d} "
                  f"{run.metrics['wall_time_s']:5.1f}s  {bridge_drops} | {_drops(host, base_host if attacks else {})}"
                  f"{overlap}{extra}")
    if args.fuzz:
        fuzz(args.fuzz)


def fuzz(inputs: int) -> None:
    """The decoder and the handshake on ``inputs`` Hypothesis inputs: exceptions and acceptances counted."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from rehabkit.hardware.link.protocol import COMMAND, STATE, Receiver, encode
    from rehabkit.hardware.security.gate import BridgeGate
    from rehabkit.hardware.security.handshake import HANDSHAKE, HostHandshake, peek_kind

    with tempfile.TemporaryDirectory() as tmp:
        key = new_key("hit-1", Path(tmp) / "hit-1.key")
    gate = BridgeGate(key, 1)
    host = HostHandshake(key, 1)
    reply, _ = gate.reply(host.next(1), ("127.0.0.1", 1))
    host.take(reply)
    reply, _ = gate.reply(host.next(2), ("127.0.0.1", 1))
    session = host.take(reply)
    seen = collections.Counter()

    @settings(max_examples=inputs, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(junk=st.binary(max_size=200), flips=st.lists(st.integers(0, 8 * 120 - 1), min_size=1, max_size=4),
           head=st.sampled_from(["junk", "state", "command", "hello", "proof"]))
    def property_(junk, flips, head):
        seen["inputs"] += 1
        base = {"junk": lambda: junk, "state": lambda: encode(STATE, 1, session.last_sent + 1, np.ones((3, 6)),
                                                                link=session),
                "command": lambda: encode(COMMAND, 1, 5, np.ones(6)), "hello": lambda: HostHandshake(key, 1).next(1),
                "proof": lambda: host.next(3)}[head]()
        data = bytearray(base)
        for bit in flips:
            if bit < 8 * len(data):
                data[bit // 8] ^= 1 << bit % 8
        data = bytes(data)
        if data == base:
            return
        try:
            if peek_kind(data) in HANDSHAKE:
                was = gate.session
                gate.reply(data, ("127.0.0.1", 1))
                seen["accepted"] += gate.session is not was
            else:
                seen["accepted"] += gate.open(data, ("127.0.0.1", 1))[0] is not None
            Receiver(STATE, 1, 6).accept(data)
        except Exception:  # noqa: BLE001 (counted: the figure is how many)
            seen["exceptions"] += 1

    t0 = time.perf_counter()
    property_()
    took = time.perf_counter() - t0
    print(f"\nfuzz: {seen['inputs']} inputs run ({inputs} asked), {took:.0f} s, exceptions {seen['exceptions']}, "
          f"accepted without the key {seen['accepted']}")


if __name__ == "__main__":
    main()
