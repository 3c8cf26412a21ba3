"""The 1 kHz loop over the robot link, against this machine's own pacing jitter, side by side.

For each scenario: an empty loop paced at 1 kHz for as long as the scenario runs (the
machine's baseline: how often a process that only sleeps to its deadlines wakes more than a
tick late), then the scenario over the link to a spawned bridge (``backend.type=hardware``),
then the same scenario in simulation for the tracking comparison. Printed per run: deadline-miss
rate of the baseline and of the link loop, round-trip median/p99, tick lateness p99,
expectations met, and tracking against the simulation. Repeat with ``--repeats``. Then the
same scenario over the lock-step link (``backend.clock=lockstep``): its loop's wall time against
the simulation's and the real-time link's, and its largest deviation from the simulated path.

    python benchmarks/link_loop.py [--repeats N] [--scenarios hit_roundtrip lexos_reaching]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from rehabkit.api import run_scenario
from rehabkit.hardware.clock import wait_until

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--scenarios", nargs="+", default=["hit_roundtrip", "lexos_reaching"])
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}\n")
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
