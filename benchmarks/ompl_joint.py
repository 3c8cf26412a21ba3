"""The ompl-joint planner over random start/goal pairs among obstacles, each path checked by MuJoCo along its timed
reference.

Robot: the URDF arm of examples/robots (4 joints, mounted 0.8 m up) in a world of a pillar, a shelf and a box
around it, and the floor. ``--pairs`` (default 200) start/goal pairs are drawn uniformly within the joint
ranges among postures free of the world (1 cm clearance, the planner's own). Each pair is planned by each
algorithm; the plan's reference is then sampled every 1 ms of its time law and every sample checked by MuJoCo's
collision detection against the true geometry (no clearance): a sample in contact makes the path "colliding".
Printed per algorithm: success rate, colliding paths, path length (joint space, rad) and its ratio to the
straight line, planning time median / p95, states checked.

    python benchmarks/ompl_joint.py [--pairs 200] [--time-limit 1.0]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from pathlib import Path

import numpy as np

from rehabkit.core.kinds.interfaces import Context, PlanningError, PlanRequest, Target
from rehabkit.core.scenario.models import World
from rehabkit.cspace.scene_check import SceneCollision

ROOT = Path(__file__).resolve().parents[1]
WORLD = {"objects": [
    {"name": "pillar", "shape": "cylinder", "size": [0.04, 0.3], "pose": {"position": [0.45, 0.0, 0.8]}},
    {"name": "shelf", "shape": "box", "size": [0.15, 0.25, 0.01], "pose": {"position": [-0.35, 0.2, 0.95]}},
    {"name": "box", "shape": "box", "size": [0.08, 0.08, 0.08], "pose": {"position": [0.1, -0.45, 0.9]}},
]}


def main() -> None:
    from rehabkit_plugins.planners.ompl_joint import OmplJointConfig, OmplJointPlanner
    from rehabkit_plugins.robots.urdf import UrdfRobot

    from rehabkit.models.files.mjcf_import import ModelFileConfig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--time-limit", type=float, default=1.0)
    args = ap.parse_args()
    world = World.model_validate(WORLD)
    ctx = Context(ROOT / "examples" / "robots", np.random.default_rng(0), 0.001, world=world)
    robot = UrdfRobot(ModelFileConfig(file="arm4.urdf", ee_frame="tip", base={"position": [0, 0, 0.8]}), ctx)
    ctx = dataclasses.replace(ctx, robot=robot)
    exact = SceneCollision(robot.model, world)
    padded = SceneCollision(robot.model, world, 0.01)
    rng = np.random.default_rng(11)
    lim = robot.model.limits
    pairs = []
    while len(pairs) < args.pairs:
        a, b = rng.uniform(lim.lower, lim.upper, (2, robot.model.dof))
        if padded.free(a) and padded.free(b):
            pairs.append((a, b))
    blocked = [exact.first_collision(a + np.linspace(0, 1, 100)[:, None] * (b - a)) >= 0 for a, b in pairs]
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; {args.pairs} pairs, {sum(blocked)} of them blocked in a straight line; "
          f"time limit {args.time_limit} s per leg")
    print(f"{'algorithm, pairs':20s} {'success':>8s} {'colliding':>9s} {'length rad':>10s} {'/straight':>9s} "
          f"{'median s':>9s} {'p95 s':>7s} {'checks':>8s}")
    for algorithm in ("rrt-connect", "rrt-star", "prm"):
        planner = OmplJointPlanner(OmplJointConfig(algorithm=algorithm, time_limit_s=args.time_limit, seed=3), ctx)
        rows = []  # (blocked, planned, colliding, length, ratio, time, checks)
        for (a, b), hard in zip(pairs, blocked):
            t0 = time.perf_counter()
            try:
                plan = planner.plan(PlanRequest(0.0, a, np.zeros_like(a), [Target("goal", q=b)], robot))
            except PlanningError:
                rows.append((hard, False, False, np.nan, np.nan, time.perf_counter() - t0, np.nan))
                continue
            elapsed = time.perf_counter() - t0
            q, _, _ = plan.trajectory.sample(np.arange(0.0, plan.trajectory.duration + 1e-9, 0.001))
            length = plan.diagnostics["path_length_rad"]
            rows.append((hard, True, exact.first_collision(q) >= 0, length,
                         length / max(np.linalg.norm(b - a), 1e-9), elapsed, plan.diagnostics["states_checked"]))
        for label, subset in (("all", rows), ("blocked", [r for r in rows if r[0]])):
            ok = [r for r in subset if r[1]]
            col = lambda i, rs=ok: np.array([r[i] for r in rs], float)  # noqa: E731
            print(f"{algorithm + ' ' + label:20s} {len(ok) / len(subset):8.1%} {sum(r[2] for r in ok):9d} "
                  f"{np.mean(col(3)):10.2f} {np.mean(col(4)):9.2f} {np.median(col(5)):9.3f} "
                  f"{np.percentile(col(5), 95):7.3f} {np.median(col(6)):8.0f}")

if __name__ == "__main__":
    main()
