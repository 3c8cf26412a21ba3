"""The robot link attacked on this machine: the HIT round trip over an authenticated link, with a second process on
the path (tests/link_attacker.py) attacking in one way per row; then the decoder and the handshake fuzzed.

Each row: a fresh bridge (lock-step, with the robot's key; real time in the last rows), the attacker between it and
the host, one HIT round trip. Printed: datagrams the attacker sent (and answers it got: refusals, at most 5 a second
to each of its sources), datagrams the bridge let in from anywhere but the host (accepted), what the bridge and the
host dropped, by reason (beyond the unattacked run's), the largest joint deviation from the unattacked run, safety
events, and the run's wall time. The first row is the unattacked run through the same relay (it is also the
earlier session the others replay). The real-time rows add the host's loop (late ticks), the age of the states it
took (the bridge's send to the host's take, p50/p99, over the run and during the flood) and the share dropped as
stale (older than ``max_age_s``).

Then the attacks of issue 49's review, each as it was demonstrated, and a summary (markdown) of what each attacker
did, what it achieved and the figure asked for:

- a flood spoofing the host's own address and session (raw sockets, tests/link_flood.py, as root in a network
  namespace of its own), against the same run unflooded: the bridge's worst tick lateness, its watchdog's time to hold;
- junk (HELLOs without a MAC1, commands without the key) from another port at 100 a second (the review's) and as fast
  as one process can send, against 6 handshakes and ``rehabkit estop clear --bridge ... --key``;
- a stranger's wrong PROOFs (naming the host's captured HELLOs, and random ones) and wrong-MAC1 HELLOs as fast as one
  process can send, during the real-time run: the host's state age p99 (a row of the table above);
- forged REFUSEDs at the host's handshakes (from elsewhere or spoofed as the bridge, naming the HELLO or blind);
- a takeover: a key holder's handshake and the README's ``estop clear`` during the real-time run (a row above).

    python benchmarks/link_attacks.py [--count 2000] [--flood-s 5] [--spoof-s 1] [--fuzz 100000]
                                      [--rows last-round,spoofed-flood,junk-flood,wrong-proof,forged-refused,takeover]
"""

from __future__ import annotations

import argparse
import collections
import json
import multiprocessing
import os
import platform
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rehabkit.api import run_scenario
from rehabkit.hardware.link import protocol
from rehabkit.hardware.security.keys import new_key

ROOT = Path(__file__).resolve().parents[1]
HIT = ROOT / "scenarios" / "hit_roundtrip.yaml"
ROWS = ("last-round", "spoofed-flood", "junk-flood", "wrong-proof", "forged-refused", "takeover")
AGES: list[tuple[float, float]] = []  # each state the host took in a real-time run: (wall time, its age [s])


def _record_ages() -> None:
    """The host's receiver of states notes each state's age as it takes it (this process only: the benchmark's
    instrument; the age is the host's clock at the take less the bridge's at the send, one clock over loopback)."""
    take = protocol.Receiver.take

    def noted(self, plain: bytes, now: float | None = None):
        if self.kind == protocol.STATE and self.max_age is not None and len(plain) >= protocol.HEADER.size:
            sent_at = protocol.HEADER.unpack_from(plain)[5]
            AGES.append((time.time(), (time.monotonic() if now is None else now) - sent_at))
        return take(self, plain, now)

    protocol.Receiver.take = noted


def _ages(span: tuple[float, float]) -> np.ndarray:
    return np.array([age for at, age in AGES if span[0] <= at <= span[1]]) * 1e3


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
                                 "--report", str(report), "--key", str(key.path)], "attacker:")
        try:
            backend = {"type": "hardware", "spawn_bridge": False, "port": port, "key_file": str(key.path)}
            backend.update({"bridge_watchdog_ms": 200, "state_timeout_s": 0.5} if realtime else {"clock": "lockstep"})
            t0 = time.time()
            AGES.clear()
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
    ap.add_argument("--spoof-s", type=float, default=1.0, help="the spoofed flood's length")
    ap.add_argument("--rows", default=",".join(ROWS), help=f"which, comma-separated, of {', '.join(ROWS)}")
    args = ap.parse_args()
    chosen = set(args.rows.split(","))
    if chosen - set(ROWS):
        ap.error(f"--rows: unknown {', '.join(sorted(chosen - set(ROWS)))} (known: {', '.join(ROWS)})")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"load {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}\n")
    rows = [("none", "", False), ("forged", "forged", False), ("replayed", "replayed", False),
            ("tampered", "tampered", False), ("wrong key", "wrong-key", False), ("flood", "flood", False),
            ("all of them", "forged,replayed,tampered,wrong-key,flood", False)] if "last-round" in chosen else []
    rows += [("none, real time", "", True)]
    rows += [("flood, real time", "flood", True)] if "last-round" in chosen else []
    rows += [("wrong PROOF/HELLO, rt", "wrong-proof", True)] if "wrong-proof" in chosen else []
    rows += [("takeover, real time", "takeover", True)] if "takeover" in chosen else []
    if not chosen & {"last-round", "wrong-proof", "takeover"}:
        rows = []
    _record_ages()
    summary: list[tuple[str, str, str, str]] = []  # (attack, what the attacker did, what it achieved, the figure)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        key = new_key("hit-1", tmp / "hit-1.key")
        clean = {}
        if rows:
            print(f"{'attack':21s} {'sent':>7s} {'answers':>7s} {'accepted':>8s} {'max dev':>9s} {'events':>6s} "
                  f"{'wall':>6s}  dropped at the bridge | at the host")
        for label, attacks, realtime in rows:
            run, stats, report, span = attacked_run(tmp, key, attacks, args.count, args.flood_s, realtime)
            if not attacks:
                clean[realtime] = (run, stats, _ages(span))
            base_run, base_stats, base_ages = clean[realtime]
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
                ages = _ages(span)
                stale = m.get("states_dropped_stale", 0.0) / max(1, len(ages))
                extra = (f" late ticks {m['deadline_misses']:.0f}, lateness p99 {m['tick_lateness_p99_ms']:.2f} ms, "
                         f"bridge holds {m['bridge_stale_holds']:.0f}; state age p50/p99 "
                         f"{np.percentile(ages, 50):.2f}/{np.percentile(ages, 99):.2f} ms, stale {100 * stale:.1f} %")
                if flood and during > 0:
                    window = _ages((max(flood["from"], span[0]), ends))
                    extra += (f" (during the flood {np.percentile(window, 50):.2f}/{np.percentile(window, 99):.2f} ms"
                              f" of {len(window)})")
                if attacks == "wrong-proof":
                    base_stale = base_run.metrics.get("states_dropped_stale", 0.0) / max(1, len(base_ages))
                    did = (f"{flood['sent']} PROOFs with wrong MACs and HELLOs with a wrong MAC1 in "
                           f"{flood['seconds']:g} s ({flood['sent'] / flood['seconds'] / 1e3:.0f} k/s, one process; "
                           f"{during:.1f} s of it during the run)")
                    got = (f"{accepted} accepted, {flood.get('answers', 0)} answers, "
                           f"{len(run.summary['safety']['events'])} safety events, max dev {dev:.2g}°")
                    fig = (f"state age p50/p99 during the flood {np.percentile(window, 50):.2f}/"
                           f"{np.percentile(window, 99):.2f} ms, stale over the run {100 * stale:.1f} % (unflooded run "
                           f"{np.percentile(base_ages, 50):.2f}/{np.percentile(base_ages, 99):.2f} ms, stale "
                           f"{100 * base_stale:.1f} %); the bridge's refusals: {_drops(stats['dropped'], {})}")
                    summary.append(("wrong-PROOF flood (a stranger)", did, got, fig))
                if attacks == "takeover" and "takeover" in report:
                    t = report["takeover"]
                    extra += (f"; takeover: handshake {t['handshake']} ({t['sent']} sent, {t['answers']} answers, "
                              f"{t['s']:g} s), estop clear exit {t['estop_clear_exit']}: {t['estop_clear_said']}")
                    did = ("a holder of the robot's key, from a port of its own during the live real-time run: a "
                           f"handshake ({t['sent']} datagrams in {t['s']:g} s), then `rehabkit estop clear hit-1 "
                           "--bridge ... --key`")
                    got = (f"handshake {t['handshake']}; estop clear exit {t['estop_clear_exit']} "
                           f"(\"{t['estop_clear_said']}\"); {accepted} of its datagrams accepted, sessions at the "
                           f"bridge {len(stats['sessions'])}, {len(run.summary['safety']['events'])} safety events, "
                           f"max dev {dev:.2g}° from the unattacked run")
                    fig = (f"the run: {m['deadline_misses']:.0f} late ticks, {m['bridge_stale_holds']:.0f} bridge "
                           f"holds, commands accepted {stats['commands_accepted']} (unattacked "
                           f"{base_stats['commands_accepted']})")
                    summary.append(("takeover attempt", did, got, fig))
            if "failed" in report:
                extra += f"; the attacker failed: {report['failed']['error']}"
            events = len(run.summary["safety"]["events"])
            bridge_drops = _drops(stats["dropped"], base_stats["dropped"] if attacks else {})
            print(f"{label:21s} {sent:7d} {answers:7d} {accepted:8d} {dev:7.2g}° {events:6d} "
                  f"{run.metrics['wall_time_s']:5.1f}s  {bridge_drops} | {_drops(host, base_host if attacks else {})}"
                  f"{overlap}{extra}", flush=True)
        if "spoofed-flood" in chosen:
            summary.append(spoofed_flood(key, args.spoof_s))
        if "junk-flood" in chosen:
            summary += [junk_flood(tmp, key, rate) for rate in (0, 100, None)]
        if "forged-refused" in chosen:
            summary.append(forged_refused(key))
    if summary:
        print("\n| attack | what the attacker did | what it achieved | the figure |\n|---|---|---|---|")
        for row in summary:
            print("| " + " | ".join(x.replace("|", "/") for x in row) + " |")
    if args.fuzz:
        fuzz(args.fuzz)


def in_own_namespace(*args: str) -> dict | None:
    """``tests/link_flood.py`` as root in a network namespace of its own (its loopback up); its JSON line, or None
    (not root, no unshare or ip: said)."""
    if os.geteuid() != 0 or shutil.which("unshare") is None or shutil.which("ip") is None:
        print("(needs root, unshare and ip: a network namespace of its own)")
        return None
    script = f"ip link set lo up && exec {sys.executable} {ROOT / 'tests' / 'link_flood.py'} {' '.join(args)}"
    done = subprocess.run(["unshare", "-n", "sh", "-c", script], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    if done.returncode:
        print(done.stderr[-2000:])
        return None
    return json.loads(done.stdout)


def spoofed_flood(key, seconds: float) -> tuple[str, str, str, str]:
    """A real-time bridge driven 0.2 s, then flooded for ``seconds`` from raw sockets with datagrams spoofing the host's
    address and naming its session (the host silent), against the same run unflooded."""
    print(f"\nspoofed flood at the host's address ({seconds:g} s, a network namespace of its own):")
    got = {}
    for label, extra in (("unflooded", ("--silent",)), ("flooded", ())):
        r = in_own_namespace(str(key.path), "--flood-s", str(seconds), "--watchdog-ms", "50", *extra)
        if r is None:
            return ("spoofed flood at the host's address", "-", "not run", "-")
        b, d = r["bridge"], r["deviation_deg"]
        got[label] = r
        print(f"  {label:9s} sent {r['sent']:8d} in {r['seconds']:.2f} s ({r['sent'] / r['seconds'] / 1e3:.0f} k/s); "
              f"bridge: {b['clock']['ticks']} ticks, late max {b['clock']['late_max_ms']:.1f} ms, p99 "
              f"{b['clock']['late_p99_ms']:.1f} ms, a period late {b['clock']['late_a_period']}; watchdog held after "
              f"{', '.join(f'{ms:.1f}' for ms in b['watchdog_holds_ms']) or '-'} ms; commands accepted "
              f"{b['commands_accepted']}; dropped {_drops(b['dropped'], {})}; posture off the start by "
              f"{d['driving']:.3f}° driving, {d['flood']:.3f}° after ({d['states_during_flood']} states)", flush=True)
    r, q = got["flooded"], got["unflooded"]
    b, c = r["bridge"], q["bridge"]
    did = (f"after one observed datagram: {r['sent']} datagrams in {r['seconds']:.2f} s "
           f"({r['sent'] / r['seconds'] / 1e3:.0f} k/s, raw sockets) with the host's address, port and session id, "
           "each a fresh sequence number, the host silent")
    holds = len(b["watchdog_holds_ms"])
    got_ = (f"{b['commands_accepted'] - c['commands_accepted']} accepted beyond the host's own (the bridge refused "
            f"{b['dropped'].get('authentication', 0)}: authentication; the rest waited in the kernel's buffer or were "
            f"dropped there); {holds} safety event{'s' * (holds != 1)}: the watchdog's hold (unflooded: "
            f"{len(c['watchdog_holds_ms'])}); max dev from the start posture {r['deviation_deg']['flood']:.3f}° "
            f"(unflooded {q['deviation_deg']['flood']:.3f}°)")
    fig = (f"worst tick {b['clock']['late_max_ms']:.1f} ms late (p99 {b['clock']['late_p99_ms']:.1f}), watchdog held "
           f"after {', '.join(f'{ms:.1f}' for ms in b['watchdog_holds_ms'])} ms; unflooded: worst "
           f"{c['clock']['late_max_ms']:.1f} ms (p99 {c['clock']['late_p99_ms']:.1f}), held after "
           f"{', '.join(f'{ms:.1f}' for ms in c['watchdog_holds_ms'])} ms; watchdog 50 ms")
    return ("spoofed flood at the host's address", did, got_, fig)


def _junk(port: int, rate: float | None, stop, sent, answers, src) -> None:
    """Junk to the bridge's port from one socket until ``stop``: HELLOs with a MAC1 it cannot make, commands without
    the key; ``rate`` a second (None: as fast as it can). Its answers counted (a process of its own)."""
    from rehabkit.hardware.link.protocol import COMMAND, PLAIN, encode, pack_bytes
    from rehabkit.hardware.security.handshake import HELLO

    rng = np.random.default_rng(3)
    pool = [PLAIN.seal(pack_bytes(HELLO, 1, 2 * i + 1, rng.bytes(64))) if i % 2 else
            encode(COMMAND, 1, 2 * i + 2, rng.uniform(-50, 50, 6)) for i in range(256)]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    src.value = sock.getsockname()[1]
    bridge, n, t = ("127.0.0.1", port), 0, time.monotonic()

    def drain() -> None:
        while True:
            try:
                sock.recv(65536)
            except (BlockingIOError, ConnectionRefusedError):
                return
            answers.value += 1

    while not stop.value:
        if rate is None:
            for data in pool:
                try:  # noqa: SIM105 (the fastest loop)
                    sock.sendto(data, bridge)
                except OSError:
                    pass
            n += len(pool)
            drain()
        else:
            sock.sendto(pool[n % len(pool)], bridge)
            n += 1
            drain()
            t += 1.0 / rate
            time.sleep(max(0.0, t - time.monotonic()))
        sent.value = n
    time.sleep(0.05)
    drain()


def junk_flood(tmp: Path, key, rate: float | None, handshakes: int = 6) -> tuple[str, str, str, str]:
    """A real-time bridge with its e-stop latched; junk from another port at ``rate`` (0: none; None: as fast as one
    process can send); meanwhile ``handshakes`` hosts, one every 0.5 s, each from a port of its own (a BYE ends each),
    then ``rehabkit estop clear hit-1 --by ... --bridge ... --key`` as the README gives it."""
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.hardware.link.protocol import pack_bytes
    from rehabkit.hardware.security.handshake import BYE, LinkRefusedError, handshake

    label = "no junk" if rate == 0 else f"junk {rate:g}/s" if rate else "junk, as fast as it can"
    where = tmp / f"junk-{rate}"
    where.mkdir()
    latch = EStopLatch.for_robot("hit", 1, where / "hit-1.json")
    latch.press("e-stop at the robot", "robot")
    bridge, port = _start([sys.executable, "-m", "rehabkit.cli", "bridge", "hit", "--key", str(key.path),
                           "--latch-file", str(latch.path), "--stats", str(where / "stats.json"), "--security-log",
                           str(where / "security.jsonl")], "bridge:")
    context = multiprocessing.get_context("fork")
    stop, sent, answers, src = (context.Value("q", 0) for _ in range(4))
    junk = context.Process(target=_junk, args=(port, rate, stop, sent, answers, src)) if rate != 0 else None
    made, times, said = 0, [], []
    try:
        t_junk = time.monotonic()
        if junk is not None:
            junk.start()
            time.sleep(0.5)
        for _ in range(handshakes):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.setblocking(False)
            seq = iter(range(1, 1 << 31))
            t0 = time.monotonic()
            try:
                session = handshake(sock, ("127.0.0.1", port), key, 1, lambda seq=seq: next(seq), timeout=5.0)
                made += 1
                times.append(1e3 * (time.monotonic() - t0))
                sock.sendto(session.seal(pack_bytes(BYE, 1, next(seq), b"", session.id)), ("127.0.0.1", port))
            except (LinkRefusedError, TimeoutError) as exc:
                said.append(str(exc))
            sock.close()
            time.sleep(0.5)
        t0 = time.monotonic()
        clear = subprocess.run([sys.executable, "-m", "rehabkit.cli", "estop", "clear", "hit-1", "--by", "Dr. Ana Ruiz",
                                "--bridge", f"127.0.0.1:{port}", "--key", str(key.path)], capture_output=True,
                               text=True, timeout=60, cwd=ROOT)
        clear_s = time.monotonic() - t0
        junk_s = time.monotonic() - t_junk
    finally:
        stop.value = 1
        if junk is not None:
            junk.join(10)
        _stop(bridge, signal.SIGINT)
    stats = json.loads((where / "stats.json").read_text())
    from_junk = stats["opened_from"].get(f"127.0.0.1:{src.value}", 0) if junk is not None else 0
    cleared = latch.latched() is None
    history = latch.cleared()
    newest = history[-1] if history else {}
    words = (clear.stdout.strip() or clear.stderr.strip()).splitlines()
    print(f"\n{label}: {sent.value} junk datagrams in {junk_s:.1f} s, {answers.value} answers to them; handshakes "
          f"made {made} of {handshakes} (ms: {', '.join(f'{t:.1f}' for t in times) or '-'}){'; ' if said else ''}"
          f"{'; '.join(said)}; estop clear exit {clear.returncode} in {clear_s:.1f} s: "
          f"{words[-1] if words else ''}; latch cleared {cleared} (history: {len(history)}, the newest by "
          f"{newest.get('cleared_by', '-')}, session {newest.get('session', '-')}, key {newest.get('key_id', '-')}); "
          f"bridge dropped {_drops(stats['dropped'], {})}",
          flush=True)
    did = ("nothing (the same handshakes and clear, unattacked)" if junk is None else
           f"{sent.value} junk datagrams (HELLOs with a MAC1 it cannot make, commands without the key) from one port "
           f"in {junk_s:.1f} s ({sent.value / junk_s:.0f}/s)") + \
        f" against {handshakes} handshakes, one every 0.5 s, then `rehabkit estop clear hit-1 --bridge ... --key`"
    got = (f"{from_junk} accepted, {answers.value} answers (refusals) to it; handshakes made {made} of {handshakes}; "
           f"estop clear exit {clear.returncode}, the latch cleared: {'yes' if cleared else 'no'}; no run, no safety "
           "event, no motion")
    fig = (f"handshake {np.median(times):.1f} ms median, {max(times):.1f} ms worst; estop clear {clear_s:.1f} s "
           "(process start to exit)") if times else f"estop clear {clear_s:.1f} s"
    return (f"junk flood vs handshakes and `estop clear` ({label})", did, got, fig)


def forged_refused(key, tries: int = 5) -> tuple[str, str, str, str]:
    """Forged REFUSEDs at ``tries`` handshakes each way (tests/link_flood.py --attack refused, a network namespace of
    its own)."""
    print(f"\nforged REFUSEDs ({tries} handshakes each way, a network namespace of its own):")
    r = in_own_namespace(str(key.path), "--attack", "refused", "--tries", str(tries))
    if r is None:
        return ("forged REFUSED", "-", "not run", "-")
    for way, got in r.items():
        print(f"  {way:32s} forged {got['forged_sent']:4d}; made {got['made']}, aborted {got['aborted']}, timed out "
              f"{got['timed_out']}{'; the host said: ' + got['said'] if got['said'] else ''}")
    did = (f"on the path (watching loopback): each HELLO answered at once by 16 REFUSEDs naming it or not, from "
           f"127.0.0.2 or spoofed as the bridge; {tries} handshakes each way")
    got = "; ".join(f"{way}: {g['aborted']} of {tries} aborted" for way, g in r.items())
    fig = "handshake ms (made): " + "; ".join(
        f"{way}: {np.median(g['ms']):.1f}" if g["ms"] else f"{way}: -" for way, g in r.items())
    return ("forged REFUSED", did, got, fig)


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
