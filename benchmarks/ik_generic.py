"""Generic numeric IK (pink on Pinocchio) on robots without an analytic one, and against the analytic IK of HIT
and ARM, side by side in one run.

For each robot, ``--targets`` (default 1,000) reachable targets: joint values drawn uniformly within the ranges,
their end-effector pose by forward kinematics. Each is asked as a whole pose (6-DoF robots), a pointing target
(the MJCF arm's tool z axis, ``free_axes: z``) or a position alone. A solve succeeds when it returns a solution
within the joint limits whose pose matches to 0.1 mm and 0.01°, about the constrained axes. Printed: success
rate, median and p95 time per target, and for HIT and ARM the analytic IK's on the same targets (time ratio).

    python benchmarks/ik_generic.py [--targets 1000]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from rehabkit.core.kinds.interfaces import Context, Robot
from rehabkit.core.setup.targets import axis_error_deg

ROOT = Path(__file__).resolve().parents[1]


def robots() -> dict[str, object]:
    import yaml
    from rehabkit_plugins.robots.arm import ArmConfig, ArmRobot
    from rehabkit_plugins.robots.dh import DHRobot
    from rehabkit_plugins.robots.hit import HitConfig, HitRobot
    from rehabkit_plugins.robots.mjcf import MjcfRobot
    from rehabkit_plugins.robots.urdf import UrdfRobot

    from rehabkit.models.dh import DHRobotSpec
    from rehabkit.models.files.mjcf_import import ModelFileConfig

    ex = ROOT / "examples" / "robots"
    ctx = Context(ex, np.random.default_rng(0), 0.001)
    dh = yaml.safe_load((ex / "dh_arm3.yaml").read_text())["robot"]
    dh.pop("type")
    return {
        "dh_arm3 (DH, 3 joints)": DHRobot(DHRobotSpec.model_validate(dh)),
        "urdf_arm4 (URDF, 4 joints)": UrdfRobot(ModelFileConfig(file="arm4.urdf", ee_frame="tip"), ctx),
        "mjcf_arm5 (MJCF, 5 joints)": MjcfRobot(ModelFileConfig(file="arm5.xml", ee_frame="tool",
                                                                 default_velocity_deg_s=90), ctx),
        "hit (6 joints)": HitRobot(HitConfig()),
        "arm (ARM, 6 arm joints)": ArmRobot(ArmConfig()),
    }


def solved(robot, sols: list[np.ndarray], want: np.ndarray, free: str) -> bool:
    """Some solution within the joint limits reaching the target (an analytic IK lists every branch)."""
    lim = robot.model.limits
    for q in sols:
        if np.any(q < lim.lower - 1e-9) or np.any(q > lim.upper + 1e-9):
            continue
        got = robot.fk(q)
        if np.linalg.norm(got[:3, 3] - want[:3, 3]) < 1e-4 and (
                free == "xyz" or axis_error_deg(got[:3, :3], want[:3, :3], free) < 0.01):
            return True
    return False


def measure(robot, poses: np.ndarray, free: str, solve) -> tuple[float, float, float]:
    ok, times = 0, []
    for want in poses:
        t0 = time.perf_counter()
        sols = solve(want, free)
        times.append(time.perf_counter() - t0)
        ok += solved(robot, sols, want, free)
    times = np.array(times) * 1000
    return ok / len(poses), float(np.median(times)), float(np.percentile(times, 95))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=1000)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}; {args.targets} targets per robot and kind")
    print(f"{'robot':28s} {'target':10s} {'solver':9s} {'success':>8s} {'median ms':>10s} {'p95 ms':>8s}")
    for name, robot in robots().items():
        rng = np.random.default_rng(7)
        lim = robot.model.limits
        qs = rng.uniform(lim.lower, lim.upper, (args.targets, robot.model.dof))
        if name.startswith("arm"):
            qs[:, np.setdiff1d(np.arange(robot.model.dof), np.arange(robot.model.dof)[robot.arm])] = 0.0
        poses = robot.fk_batch(qs)
        dof = len(np.arange(robot.model.dof)[robot.arm]) if name.startswith("arm") else robot.model.dof
        kinds = {3: ["xyz"], 4: ["xyz"], 5: ["z", "xyz"]}.get(dof, ["", "xyz"])
        for free in kinds:
            label = {"": "pose", "z": "pointing", "xyz": "position"}[free]
            rate, med, p95 = measure(robot, poses, free, lambda p, f, r=robot: r.numeric_ik.solve(p, free=f))
            print(f"{name:28s} {label:10s} {'numeric':9s} {rate:8.1%} {med:10.2f} {p95:8.2f}   (every branch)")
            rate, med, p95 = measure(robot, poses, free,
                                     lambda p, f, r=robot: r.numeric_ik.solve(p, free=f, first=True))
            print(f"{'':28s} {label:10s} {'numeric':9s} {rate:8.1%} {med:10.2f} {p95:8.2f}   (first found)")
            if free == "" and type(robot).ik is not Robot.ik:
                a_rate, a_med, a_p95 = measure(robot, poses, free, lambda p, f, r=robot: r.ik(p))
                print(f"{'':28s} {label:10s} {'analytic':9s} {a_rate:8.1%} {a_med:10.2f} {a_p95:8.2f}"
                      f"   (numeric first-found / analytic median time: {med / a_med:.0f}x)")


if __name__ == "__main__":
    main()
