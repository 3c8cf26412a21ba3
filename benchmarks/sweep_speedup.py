"""A sweep on Ray against the same sweep run serially, side by side in one run.

The L-Exos planner comparison (``scenarios/lexos_planner_trial.yaml``: 4 planners x N
start/goal seeds) is run twice from scratch: serially in this process, then on a local Ray
with ``--workers`` CPUs. Printed: wall time of each (the Ray one with and without starting
Ray), runs per second, the speed-up, the machine's own ceiling (the same pure-CPU work in
``--workers`` processes against one), and whether the two gave the same rows (wall-clock
figures aside).

    python benchmarks/sweep_speedup.py [--seeds 100] [--workers 2]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import tempfile
import time
from pathlib import Path

import ray

from rehabkit.sweep.engine import run_sweep
from rehabkit.sweep.tables import reproducible

TRIAL = Path(__file__).resolve().parents[1] / "scenarios" / "lexos_planner_trial.yaml"


def _spin(n: int) -> int:
    s = 0
    for i in range(n):
        s += i * i % 7
    return s


def ceiling(workers: int, n: int = 6_000_000) -> float:
    """This machine's speed-up for perfectly parallel CPU-bound work: ``workers`` processes vs one (a VM's
    vCPUs may share physical cores)."""
    t0 = time.perf_counter()
    for _ in range(workers):
        _spin(n)
    one = time.perf_counter() - t0
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        pool.map(_spin, [1000] * workers)  # started
        t0 = time.perf_counter()
        pool.map(_spin, [n] * workers)
        return one / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"ray {ray.__version__}")
    with tempfile.TemporaryDirectory() as tmp:
        serial = run_sweep(TRIAL, None, args.seeds, Path(tmp) / "serial", serial=True)
        t0 = time.perf_counter()
        ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False, logging_level="WARNING")
        start = time.perf_counter() - t0
        parallel = run_sweep(TRIAL, None, args.seeds, Path(tmp) / "ray")
        ray.shutdown()
    n = len(serial.records)
    print(f"\n{n} runs (4 planners x {args.seeds} seeds)")
    print(f"{'':24s} {'wall [s]':>9s} {'runs/s':>8s}")
    print(f"{'serial (this process)':24s} {serial.wall_s:9.1f} {n / serial.wall_s:8.2f}")
    print(f"{f'Ray, {args.workers} workers':24s} {parallel.wall_s:9.1f} {n / parallel.wall_s:8.2f}"
          f"   (+ {start:.1f} s to start Ray)")
    print(f"speed-up: {serial.wall_s / parallel.wall_s:.2f}x (Ray's start included: "
          f"{serial.wall_s / (parallel.wall_s + start):.2f}x)")
    print(f"this machine's ceiling: {args.workers} processes of pure CPU work vs one: {ceiling(args.workers):.2f}x "
          "(measured now)")
    same = reproducible(serial.records) == reproducible(parallel.records)
    print(f"rows identical (wall-clock figures aside): {same}; failed runs: serial {len(serial.failed)}, "
          f"Ray {len(parallel.failed)}")


if __name__ == "__main__":
    main()
