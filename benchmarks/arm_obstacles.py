"""ARM box-avoid planner on random environments like the paper's simulation study.

* ``--envs`` (default 10,000) rooms with 10 obstacles of random size (2–15 cm half
  extents) and random orientation, overlapping ones included, random start and goal in
  free space; the gripper margin inflates every obstacle. Every returned path is checked
  segment by segment against every inflated obstacle with the exact tests of
  ``rehabkit.geometry.solids`` (independently of the planner's own final check).
  Printed: colliding paths returned, explicit failures (NoPathError) by reason, how
  many needed an overlap merge, median / p99 planning time.
* Planning time against obstacle count 1..100, with the room volume scaled so that the
  obstacle density stays that of the 10-obstacle room: median time per count and the
  time ratio to the 10-obstacle case, to show the growth is about linear.

    python benchmarks/arm_obstacles.py [--envs 10000] [--mixed]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections import Counter

import numpy as np
from scipy.spatial.transform import Rotation

from rehabkit.geometry.box_avoid import NoPathError, plan_path
from rehabkit.geometry.solids import Box, Cylinder, Sphere, path_hits

MARGIN = 0.03  # half the gripper width, m


def environment(rng: np.random.Generator, n: int, side: float, mixed: bool) -> list:
    obstacles = []
    for k in range(n):
        c = rng.uniform(-side / 2, side / 2, 3)
        kind = k % 4 if mixed else 0
        if kind == 2:
            obstacles.append(Sphere(c, rng.uniform(0.03, 0.12), f"sphere{k}"))
        elif kind == 3:
            obstacles.append(
                Cylinder(c, rng.normal(size=3), rng.uniform(0.03, 0.1), rng.uniform(0.03, 0.15), f"cyl{k}")
            )
        else:
            rot = Rotation.random(random_state=rng).as_matrix()
            obstacles.append(Box(c, rng.uniform(0.02, 0.15, 3), rot, f"box{k}"))
    return obstacles


def free_point(rng: np.random.Generator, obstacles: list, side: float) -> np.ndarray:
    while True:
        p = rng.uniform(-side / 2, side / 2, 3)
        if not any(o.inflated(MARGIN).contains(p) for o in obstacles):
            return p


def run(rng, n: int, side: float, envs: int, mixed: bool) -> dict:
    times, reasons, colliding, merged, overlapping = [], Counter(), 0, 0, 0
    for _ in range(envs):
        obs = environment(rng, n, side, mixed)
        boxes = [o.inflated(MARGIN).bounding_box() for o in obs]
        overlapping += any(
            np.linalg.norm(a.center - b.center) < np.linalg.norm(a.half) + np.linalg.norm(b.half)
            for i, a in enumerate(boxes)
            for b in boxes[i + 1 :]
        )
        s, g = free_point(rng, obs, side), free_point(rng, obs, side)
        t0 = time.perf_counter()
        try:
            res = plan_path(s, g, obs, margin=MARGIN)
        except NoPathError as err:
            times.append(time.perf_counter() - t0)
            reasons[str(err).split(":")[0].split("'")[0].strip()] += 1
            continue
        times.append(time.perf_counter() - t0)
        merged += res.merges > 0
        colliding += any(path_hits(res.path, o.inflated(MARGIN)) for o in obs)
    t = np.array(times) * 1e3
    return {
        "colliding": colliding,
        "failures": sum(reasons.values()),
        "reasons": reasons,
        "merged": merged,
        "overlap_candidates": overlapping,
        "median_ms": float(np.median(t)),
        "p99_ms": float(np.percentile(t, 99)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--envs", type=int, default=10_000)
    ap.add_argument("--mixed", action="store_true", help="boxes, spheres and cylinders instead of boxes only")
    args = ap.parse_args()
    cpu = platform.processor() or platform.machine()
    print(f"machine: {cpu}, {os.cpu_count()} cpus, python {platform.python_version()}")
    rng = np.random.default_rng(2004)
    side10 = 1.6  # m: the ARM's reach sphere fits
    r = run(rng, 10, side10, args.envs, args.mixed)
    print(f"\n{args.envs} environments, 10 {'mixed ' if args.mixed else ''}obstacles, margin {MARGIN} m:")
    print(f"  colliding paths returned : {r['colliding']}")
    print(f"  explicit failures        : {r['failures']} ({100 * r['failures'] / args.envs:.2f} %)")
    for reason, count in r["reasons"].most_common():
        print(f"      {count:5d}  {reason}")
    print(f"  scenes with (bounding-sphere) overlaps: {r['overlap_candidates']}, paths needing a merge: {r['merged']}")
    print(f"  planning time median {r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms")

    print("\nobstacles  room side (m)  median ms  ratio to n=10  failures")
    per = max(100, args.envs // 50)
    rows = []
    for n in (1, 2, 5, 10, 20, 50, 100):
        side = side10 * (n / 10) ** (1 / 3)
        rows.append((n, side, run(np.random.default_rng(n), n, side, per, args.mixed)))
    base = next(row[2]["median_ms"] for row in rows if row[0] == 10)
    for n, side, res in rows:
        print(f"{n:9d}  {side:13.2f}  {res['median_ms']:9.3f}  {res['median_ms'] / base:13.2f}  {res['failures']:8d}")


if __name__ == "__main__":
    main()
