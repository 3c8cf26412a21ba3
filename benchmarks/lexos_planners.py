"""L-Exos workspace planners: the paper's Monte Carlo comparison, and the look-up table's costs.

* 600 random start/goal pairs of inner voxels that a straight line cannot link (the same
  pairs as a sweep of ``scenarios/lexos_planner_trial.yaml`` over seeds 0..599: ``--from-sweep``);
  A*, weighted A* (h x 1.5), hill and beam (k = 5 cm) on each; mean ± std of the
  decimated (n = 3) path length and of planning time, over the pairs every planner
  solved; failures counted. Table printed, plot saved (PNG).
* Straight-segment test through the table vs sampling the segment at 100 points
  with inverse kinematics (ratio, same run); proxy-point look-up counts.
* Table build time (cache bypassed) and size.
* clik-pd controller: cost of one 1 kHz cycle (closed-loop IK + joint PD + gravity).

    python benchmarks/lexos_planners.py [--pairs 600] [--png out/lexos_planners.png]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
from rehabkit_plugins.robots.lexos import LexosConfig, LexosRobot

from rehabkit.workspace.grid import BOUNDARY
from rehabkit.workspace.sampling import random_inner, random_inner_not_straight
from rehabkit.workspace.search import SearchFailedError, astar, beam, decimate, hill, path_length

PLANNERS = {
    "A*": lambda ws, a, b: astar(ws, a, b),
    "weighted A* (1.5h)": lambda ws, a, b: astar(ws, a, b, weight=1.5),
    "hill": lambda ws, a, b: hill(ws, a, b),
    "beam (k=5 cm)": lambda ws, a, b: beam(ws, a, b, k=0.05),
}


def random_pairs(ws, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pair k: the draws of ``scenarios/lexos_planner_trial.yaml`` at seed k (start: stream (k, 0); goal: stream
    (k, 1), redrawn until a straight line cannot link it), so ``rehabkit sweep`` of that scenario plans the
    same pairs."""
    pairs = []
    for k in range(n):
        a = random_inner(ws, np.random.default_rng([k, 0]))
        pairs.append((a, random_inner_not_straight(ws, np.random.default_rng([k, 1]), a)))
    return pairs


SWEEP_NAMES = {"voxel-astar": "A*", "voxel-wastar": "weighted A* (1.5h)", "voxel-hill": "hill",
               "voxel-beam": "beam (k=5 cm)"}


def compare_with_sweep(directory: Path, lengths: dict[str, np.ndarray]) -> None:
    """The sweep's per-run decimated lengths against this benchmark's, pair by pair (seed = pair index)."""
    from rehabkit.sweep.tables import read_parquet

    rows = read_parquet(directory / "results.parquet")
    print(f"\nagainst the sweep in {directory} ({len(rows)} runs):")
    print(f"{'planner':20} {'pairs':>6} {'same length':>12} {'max |diff| [m]':>15} {'straight in sweep':>18} "
          f"{'failures sweep/here':>20}")
    for plugin, name in SWEEP_NAMES.items():
        mine = {r["seed"]: r for r in rows if r["planner.type"] == plugin}
        seeds = [s for s in mine if s < len(lengths[name])]
        length = {s: mine[s].get("metric.decimated_path_length_m") for s in seeds}
        both = [s for s in seeds if length[s] is not None and not np.isnan(lengths[name][s])]
        diff = max((abs(length[s] - lengths[name][s]) for s in both), default=0.0)
        same = sum(abs(length[s] - lengths[name][s]) < 1e-9 for s in both)
        # the run plans from the hand where IK put it (start to ~1e-12): on a voxel edge the table's straight-line
        # test can then pass where it failed from the voxel centre, and no search is needed
        straight = sum(length[s] is None and bool(mine[s].get("metric.straight_legs")) for s in seeds)
        fails = (sum(length[s] is None and not mine[s].get("metric.straight_legs") for s in seeds),
                 int(np.isnan(lengths[name][seeds]).sum()))
        print(f"{name:20} {len(seeds):6d} {same:12d} {diff:15.2e} {straight:18d} {fails[0]:>10d}/{fails[1]:<9d}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=600)
    ap.add_argument("--png", default="out/lexos_planners.png")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--from-sweep", type=Path, default=None, metavar="DIR",
                    help="also compare with a sweep of scenarios/lexos_planner_trial.yaml, pair by pair")
    args = ap.parse_args()
    robot = LexosRobot(LexosConfig())
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")

    t0 = time.perf_counter()
    ws = robot.workspace(progress=False, use_cache=False)
    build = time.perf_counter() - t0
    counts = np.bincount(ws.labels.ravel(), minlength=3)
    print(f"look-up table: built in {build:.1f} s (cache bypassed), {ws.shape[0]}x{ws.shape[1]}x{ws.shape[2]} "
          f"voxels of {ws.resolution * 100:.0f} cm, {ws.nbytes / 1e6:.2f} MB; "
          f"inner {counts[2]}, boundary {counts[1]}, unreachable {counts[0]}")

    rng = np.random.default_rng(args.seed)
    pairs = random_pairs(ws, args.pairs)
    lengths = {k: np.full(len(pairs), np.nan) for k in PLANNERS}
    times = {k: np.full(len(pairs), np.nan) for k in PLANNERS}
    for i, (a, b) in enumerate(pairs):
        for name, plan in PLANNERS.items():
            t = time.perf_counter()
            try:
                path = plan(ws, a, b)
            except SearchFailedError:
                continue
            times[name][i] = time.perf_counter() - t
            lengths[name][i] = path_length(decimate(path, 3))
    solved = np.all([~np.isnan(lengths[k]) for k in PLANNERS], axis=0)
    print(f"\n{len(pairs)} start/goal pairs not linkable by a straight line; statistics over the "
          f"{solved.sum()} every planner solved")
    print(f"{'planner':20} {'failures':>8} {'decimated length [m]':>22} {'vs A*':>7} {'time [ms]':>18} {'A*/this':>8}")
    ref_len, ref_t = np.mean(lengths["A*"][solved]), np.mean(times["A*"][solved])
    rows = []
    for name in PLANNERS:
        L, T = lengths[name][solved], times[name][solved] * 1e3
        fails = int(np.isnan(lengths[name]).sum())
        rows.append((name, L.mean(), L.std(), T.mean(), T.std()))
        print(f"{name:20} {fails:8d} {L.mean():12.4f} ± {L.std():.4f} {L.mean() / ref_len - 1:+7.1%} "
              f"{T.mean():9.2f} ± {T.std():6.2f} {ref_t * 1e3 / T.mean():8.1f}")

    if args.from_sweep is not None:
        compare_with_sweep(args.from_sweep, lengths)

    # straight-segment test: table vs inverse kinematics at 100 samples
    segs = [pairs[i] for i in range(min(200, len(pairs)))]

    def best_of(fn, repeats=5):
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            for a, b in segs:
                fn(a, b)
            times.append((time.perf_counter() - t) / len(segs))
        return min(times)

    t_table = best_of(ws.segment_inner)
    t_ik = best_of(lambda a, b: robot.reachable(a + np.linspace(0, 1, 100)[:, None] * (b - a)))
    print(f"\nstraight-segment test: table {t_table * 1e6:.0f} us, IK at 100 points {t_ik * 1e6:.0f} us, "
          f"ratio {t_ik / t_table:.0f}x")

    used = []
    inner = ws.inner_points()
    for start in inner[rng.integers(len(inner), size=500)]:
        d = rng.normal(size=3)
        target = start + rng.uniform(0.3, 1.2) * d / np.linalg.norm(d)
        if not ws.reachable(target):
            used.append(ws.proxy_point(start, target, level=BOUNDARY)[1])
    print(f"proxy point: {len(used)} targets outside the workspace, bisection look-ups max {max(used)}, "
          f"mean {np.mean(used):.2f} (plus one to find the target unreachable)")

    from rehabkit_plugins.controllers.clik_pd import ClikPD, ClikPDConfig

    from rehabkit.core.kinds.interfaces import Context

    ctrl = ClikPD(ClikPDConfig(), Context(Path("."), np.random.default_rng(0), 0.001, robot=robot))
    q = np.radians([20.0, -45.0, 0.0, -70.0])
    x = robot.fk(q)[:3, 3]
    line = x + np.linspace(0, 0.1, 5000)[:, None] * np.array([1.0, 0.5, 0.2])
    costs = []
    for _ in range(5):
        t = time.perf_counter()
        for xr in line:
            ctrl.compute(0.0, q, np.zeros(4), xr, np.zeros(3), np.zeros(3))
        costs.append((time.perf_counter() - t) / len(line))
    print(f"clik-pd controller: {min(costs) * 1e6:.1f} us per cycle (best of 5 x {len(line)} cycles)")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    names = [r[0] for r in rows]
    ax1.bar(names, [r[1] for r in rows], yerr=[r[2] for r in rows], capsize=4, color="#4a7fb5")
    ax1.set_ylabel("decimated path length [m]")
    ax2.bar(names, [r[3] for r in rows], yerr=[r[4] for r in rows], capsize=4, color="#d08a3c")
    ax2.set_yscale("log")
    ax2.set_ylabel("planning time [ms]")
    for ax in (ax1, ax2):
        ax.tick_params(axis="x", rotation=20)
    fig.suptitle(f"L-Exos workspace planners, {solved.sum()} random non-straight pairs (mean ± std)")
    fig.tight_layout()
    Path(args.png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.png, dpi=120)
    print(f"plot: {args.png}")


if __name__ == "__main__":
    main()
