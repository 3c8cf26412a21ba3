"""The 1 kHz loop over the robot link, against this machine's own pacing jitter, side by side.

For each scenario: an empty loop paced at 1 kHz for as long as the scenario runs (the
machine's baseline: how often a process that only sleeps to its deadlines wakes more than a
tick late), then the scenario over the link to a spawned bridge (``backend.type=hardware``),
then the same scenario in simulation for the tracking comparison. Printed per run: deadline-miss
rate of the baseline and of the link loop, round-trip median/p99, tick lateness p99,
expectations met, and tracking against the simulation. Repeat with ``--repeats``. Then the
same scenario over the lock-step link (``backend.clock=lockstep``): its loop's wall time against
the simulation's and the real-time link's, and its largest deviation from the simulated path.

Then authentication (``--auth``, default on): the cost of a handshake at each end and of refusing a stranger's
datagram, the cost of sealing and opening one datagram in a session against the checksum of a link without a key
[µs], and the HIT round trip in real time without a key and with one, alternating,
side by side: deadline misses, tick lateness, round trips.

    python benchmarks/link_loop.py [--repeats N] [--scenarios hit_roundtrip lexos_reaching] [--no-auth]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from rehabkit.api import run_scenario
from rehabkit.hardware.link.clock import wait_until

ROOT = Path(__file__).resolve().parents[1]


def baseline(seconds: float) -> tuple[float, float]:
    """Share of 1 kHz deadlines an idle paced loop wakes more than a tick late, and its p99 lateness [ms]."""
    late = []
    deadline = time.monotonic()
    for _ in range(int(seconds * 1000)):
        deadline += 0.001
        wait_until(deadline)
        late.append(time.monotonic() - deadline)
    late = np.array(late) * 1e3
    return float(np.mean(late > 1.0)), float(np.percentile(late, 99))


def handshake_cost(n: int = 500) -> None:
    """A whole handshake in process, each end's share [us] (X25519 key pairs and exchange, HKDF, the proofs, MAC1),
    the sizes of its messages [B], and what the bridge spends refusing a stranger's datagram [us]: a HELLO without
    MAC1, a PROOF for no challenge, a datagram of the session from another address."""
    import tempfile

    from rehabkit.hardware.link.protocol import COMMAND, PLAIN, encode, pack_bytes
    from rehabkit.hardware.security.gate import BridgeGate
    from rehabkit.hardware.security.handshake import HELLO, PROOF, HostHandshake
    from rehabkit.hardware.security.keys import new_key

    with tempfile.TemporaryDirectory() as tmp:
        key = new_key("hit-1", Path(tmp) / "hit-1.key")
    at = ("127.0.0.1", 9)
    host_s = bridge_s = 0.0
    gate = BridgeGate(key, 1)
    for i in range(n):
        gate.end()
        t0 = time.perf_counter()
        host = HostHandshake(key, 1)
        hello = host.next(1)
        t1 = time.perf_counter()
        challenge, _ = gate.reply(hello, at, float(i))
        t2 = time.perf_counter()
        host.take(challenge)
        proof = host.next(2)
        t3 = time.perf_counter()
        welcome, _ = gate.reply(proof, at, float(i))
        t4 = time.perf_counter()
        assert host.take(welcome) is not None
        t5 = time.perf_counter()
        host_s += (t1 - t0) + (t3 - t2) + (t5 - t4)
        bridge_s += (t2 - t1) + (t4 - t3)
    print(f"{'handshake [us]':24s} host {1e6 * host_s / n:6.0f}   bridge {1e6 * bridge_s / n:6.0f}   sizes [B]: HELLO "
          f"{len(hello)}, CHALLENGE {len(challenge)}, PROOF {len(proof)}, WELCOME {len(welcome)}")
    stranger = ("127.0.0.1", 10)
    junk = PLAIN.seal(pack_bytes(HELLO, 1, 1, bytes(64)))
    wrong = PLAIN.seal(pack_bytes(PROOF, 1, 2, bytes(64)))
    sealed = encode(COMMAND, 1, 10**6, np.zeros(6), link=gate.session)
    for label, act in (("HELLO without MAC1", lambda j: gate.reply(junk, stranger, 1e6 + j)),
                       ("PROOF, no challenge", lambda j: gate.reply(wrong, at, 1e6)),
                       ("session's, elsewhere", lambda j: gate.open(sealed, stranger))):
        t0 = time.perf_counter()
        for j in range(20 * n):
            act(j)
        print(f"{'refusing ' + label:32s} {1e6 * (time.perf_counter() - t0) / (20 * n):6.2f} us")


def datagram_cost(n: int = 20000) -> None:
    """Per datagram, a STATE of 6 joints (the bridge sends one a tick) and a COMMAND (the host's): encoded and taken
    in, without a key (CRC-32) and in a session (ChaCha20-Poly1305) [µs]."""
    import tempfile

    from rehabkit.hardware.link.protocol import COMMAND, STATE, Receiver, encode
    from rehabkit.hardware.security.gate import BridgeGate
    from rehabkit.hardware.security.handshake import HostHandshake
    from rehabkit.hardware.security.keys import new_key

    with tempfile.TemporaryDirectory() as tmp:
        key = new_key("hit-1", Path(tmp) / "hit-1.key")
    gate, host = BridgeGate(key, 1), HostHandshake(key, 1)
    for seq in (1, 2):
        reply, _ = gate.reply(host.next(seq), ("127.0.0.1", 9))
        session = host.take(reply)
    state, cmd = np.arange(18.0).reshape(3, 6), np.arange(6.0)
    print(f"{'per datagram [us]':24s} {'encode':>8s} {'take in':>8s} {'size [B]':>9s}")
    for label, kind, values, joints in (("STATE", STATE, state, 6), ("COMMAND", COMMAND, cmd, 6)):
        for keyed in (False, True):
            rx = Receiver(kind, 1, joints)
            t0 = time.perf_counter()
            if keyed:  # the host seals commands for the bridge, the bridge states for the host: time one direction
                sealer, opener = (session, gate) if kind == COMMAND else (gate, session)
                data = [encode(kind, 1, sealer.last_sent + 1 + i if sealer is session else gate.next_seq(), values,
                               sent_at=1.0, link=sealer) for i in range(n)]
                t1 = time.perf_counter()
                for d in data:
                    opened = opener.open(d, ("127.0.0.1", 9)) if opener is gate else opener.open(d)
                    rx.take(opened[0])
            else:
                data = [encode(kind, 1, i + 1, values, sent_at=1.0) for i in range(n)]
                t1 = time.perf_counter()
                for d in data:
                    rx.accept(d)
            t2 = time.perf_counter()
            assert rx.accepted == n
            print(f"{label + (' sealed' if keyed else ' CRC-32'):24s} {1e6 * (t1 - t0) / n:8.2f} "
                  f"{1e6 * (t2 - t1) / n:8.2f} {len(data[0]):9d}")


def auth_side_by_side(repeats: int) -> None:
    """The HIT round trip over the real-time link without a key and with one, alternating."""
    import tempfile

    from rehabkit.hardware.security.keys import new_key

    path = ROOT / "scenarios" / "hit_roundtrip.yaml"
    with tempfile.TemporaryDirectory() as tmp:
        key = new_key("hit-1", Path(tmp) / "hit-1.key")
        print(f"\n{'HIT real time':16s} {'miss':>7s} {'late p99':>9s} {'late max':>9s} {'rtt p50':>8s} {'rtt p99':>8s} "
              f"{'dropped':>8s} {'events':>6s}")
        for _ in range(repeats):
            for label, extra in (("no key", []), ("authenticated", [f"backend.key_file={key.path}"])):
                m = run_scenario(path, ["backend.type=hardware", *extra]).metrics
                print(f"{label:16s} {m['deadline_miss_rate']:7.2%} {m['tick_lateness_p99_ms']:8.2f}  "
                      f"{m['tick_lateness_max_ms']:8.2f}  {m['rtt_median_ms']:8.2f} {m['rtt_p99_ms']:8.2f} "
                      f"{m['states_dropped']:8.0f} {m['safety_events']:6.0f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--scenarios", nargs="+", default=["hit_roundtrip", "lexos_reaching"])
    ap.add_argument("--no-auth", dest="auth", action="store_false", help="skip the authentication figures")
    ap.add_argument("--auth-only", action="store_true", help="only the authentication figures")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}\n")
    if args.auth:
        handshake_cost()
        datagram_cost()
        auth_side_by_side(args.repeats)
        print()
    if args.auth_only:
        return
    print(f"{'scenario':16s} {'baseline miss':>13s} {'link miss':>9s} {'ratio':>6s} {'late p99':>9s} "
          f"{'rtt p50':>8s} {'rtt p99':>8s} {'expect':>7s} {'rms vs sim':>10s}")
    for name in args.scenarios:
        path = ROOT / "scenarios" / f"{name}.yaml"
        sim = run_scenario(path)
        for _ in range(args.repeats):
            base_miss, _ = baseline(sim.summary["metrics"]["sim_time_s"])
            hw = run_scenario(path, ["backend.type=hardware"])
            m = hw.metrics
            n = min(len(sim.trace.x if sim.trace.x is not None else sim.trace.q), len(hw.trace.q))
            if sim.trace.x is not None and hw.trace.x is not None:  # Cartesian scenarios: the hand [mm]
                rms = f"{1e3 * np.sqrt(np.mean(np.sum((sim.trace.x[:n] - hw.trace.x[:n]) ** 2, axis=1))):.2f} mm"
            else:
                rms = f"{np.degrees(np.sqrt(np.mean((sim.trace.q[:n] - hw.trace.q[:n]) ** 2))):.3f} deg"
            met = sum(e["passed"] for e in hw.summary["expectations"])
            miss = m["deadline_miss_rate"]
            print(f"{name:16s} {base_miss:13.2%} {miss:9.2%} {miss / max(base_miss, 1e-4):6.1f} "
                  f"{m['tick_lateness_p99_ms']:8.2f}  {m['rtt_median_ms']:8.2f} {m['rtt_p99_ms']:8.2f} "
                  f"{met:>3d}/{len(hw.summary['expectations']):<3d} {rms:>10s}")
        ls = run_scenario(path, ["backend.type=hardware", "backend.clock=lockstep"])
        wall = {k: r.summary["metrics"]["wall_time_s"] for k, r in (("sim", sim), ("lockstep", ls), ("realtime", hw))}
        dev = np.degrees(np.abs(sim.trace.q - ls.trace.q).max()) if len(sim.trace.q) == len(ls.trace.q) else np.nan
        print(f"{name:16s} lock-step loop {wall['lockstep']:.2f} s = {wall['lockstep'] / wall['sim']:.1f}x the "
              f"simulation's, {wall['lockstep'] / wall['realtime']:.2f}x the real-time link's; "
              f"{1e6 * wall['lockstep'] / len(ls.trace.q):.0f} us a tick; max deviation from the simulation "
              f"{dev:.2g} deg")


if __name__ == "__main__":
    main()
