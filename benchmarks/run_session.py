"""A run session taken and put back: what a snapshot and a restore cost on each built-in scenario, whether the run
goes on bit for bit after it, a learning environment's reset restored against built, and a forked replay against a
full one.

    python benchmarks/run_session.py [--repeats 5] [--scenarios hit_myoarm,hit_roundtrip]

Figures are printed, not asserted (the tests assert what holds on any machine: tests/test_run_session.py).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("hit_roundtrip", "hit_myoarm", "lexos_reaching", "lexos_patient", "lexos_myoarm", "capaman_obstacle",
             "coman_juggling", "arm_replay")


def _ms(seconds: list[float]) -> str:
    return f"{statistics.median(seconds) * 1e3:8.2f}"


def snapshots(names: list[str], repeats: int) -> None:
    from rehabkit.core.run.loop import run_loop
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.run.snapshot import restore, snapshot
    from rehabkit.core.scenario.loader import load_scenario

    print(f"{'scenario':18} {'steps':>6} {'snapshot ms':>12} {'restore ms':>11}  after a restore at 40 %")
    for name in names:
        session = Runner(load_scenario(ROOT / "scenarios" / f"{name}.yaml", {"expect": None})).start()
        n = session.setup.schedule.steps
        run_loop(session, k_to=int(0.4 * n))
        taken, put = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            snap = snapshot(session)
            taken.append(time.perf_counter() - t0)
        run_loop(session)
        first = session.trace.trimmed(session.loop.k)
        q, tau, end = first.q.copy(), first.tau.copy(), session.loop.k
        for _ in range(repeats):
            t0 = time.perf_counter()
            restore(session, snap)
            put.append(time.perf_counter() - t0)
        run_loop(session)
        again = session.trace.trimmed(session.loop.k)
        same = session.loop.k == end and np.array_equal(again.q, q) and np.array_equal(again.tau, tau)
        print(f"{name:18} {n:6d} {_ms(taken):>12} {_ms(put):>11}  {'bit for bit' if same else 'DIFFERS'}")
        session.setup.backend.close()


def gym_reset(repeats: int) -> None:
    from rehabkit.gym.env import ScenarioEnv

    env = ScenarioEnv(ROOT / "scenarios" / "hit_myoarm.yaml")
    restored, built = [], []
    for seed in range(repeats):
        t0 = time.perf_counter()
        _, info = env.reset(seed=seed + 1)
        restored.append(time.perf_counter() - t0)
        assert info["reset"] == "restored"
    for seed in range(repeats):
        env._start = None  # (as before sessions could be restored: every reset builds the run)
        t0 = time.perf_counter()
        env.reset(seed=seed + 1)
        built.append(time.perf_counter() - t0)
    env.close()
    print(f"\ngym reset on hit_myoarm (median of {repeats}): restored {_ms(restored).strip()} ms, built "
          f"{_ms(built).strip()} ms ({statistics.median(built) / statistics.median(restored):.0f}×)")


def forked_replay(repeats: int) -> None:
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.rehab.replay import replay

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        original = Runner(load_scenario(ROOT / "scenarios" / "hit_roundtrip.yaml"), out_dir=out / "run").run()
        change = ["controller.kp=[90, 90, 15, 18, 1.6, 1.8]"]
        full, forked = [], []
        for i in range(repeats):
            t0 = time.perf_counter()
            whole = replay(out / "run", change, out / f"full{i}")
            full.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            fork = replay(out / "run", change, out / f"fork{i}", fork_at=4.0)
            forked.append(time.perf_counter() - t0)
        k = fork.fork["step"]
        q0, qf, qw = original.trace.q, fork.result.trace.q, whole.result.trace.q
        deg = np.degrees
        print(f"\nreplay of hit_roundtrip with kp/10 (median of {repeats}): full {_ms(full).strip()} ms, forked at 4 s "
              f"{_ms(forked).strip()} ms (the recorded part run again to the fork, then the rest)")
        print(f"  before the fork, forked vs recorded: max |Δq| = {deg(np.abs(qf[:k] - q0[:k]).max()):.3g}°; "
              f"full replay vs recorded: {deg(np.abs(qw[:k] - q0[:k]).max()):.3g}°")
        print(f"  after it: forked vs recorded {deg(np.abs(qf[k:] - q0[k:]).max()):.3g}°, tracking rms "
              f"{fork.result.summary['metrics']['tracking_rms_deg']:.3g}° (full replay "
              f"{whole.result.summary['metrics']['tracking_rms_deg']:.3g}°, recorded "
              f"{original.summary['metrics']['tracking_rms_deg']:.3g}°)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()
    print(f"{platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
          f"load {os.getloadavg()[0]:.2f}\n")
    snapshots(args.scenarios.split(","), args.repeats)
    gym_reset(args.repeats)
    forked_replay(max(1, args.repeats // 2))


if __name__ == "__main__":
    main()
