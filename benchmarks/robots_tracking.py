"""How well the arms example-robot-data ships track at default settings, with their own dynamics as the URDF
declares them (damping, Coulomb friction): a slow posture-to-posture move, 40 % → 60 % of each joint's range (a
continuous joint gets ±180° from the scenario), a 3-s cubic, a joint PD at ``gains: auto`` (with the
inverse-dynamics feedforward, its default there), nothing else set. Each run goes through the CLI as a user's
would (``validate``, then ``run``); the table gives the joints (prismatic ones counted), the dynamics the file
declares, the tracking rms/max over the revolute joints, the expectations' verdicts and what the run said.

    python benchmarks/robots_tracking.py [--only xArm7]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import yaml

ERD = Path(__import__("cmeel").__file__).parent.parent / "cmeel.prefix" / "share" / "example-robot-data" / "robots"

ROBOTS = [  # (name, file under example-robot-data's robots/, end effector)
    ("Panda", "panda_description/urdf/panda.urdf", "panda_hand_tcp"),
    ("UR5", "ur_description/urdf/ur5_robot.urdf", "tool0"),
    ("UR5 on a 1.5-m stand", "ur_description/urdf/ur5_robot.urdf", "tool0"),
    ("UR10", "ur_description/urdf/ur10_robot.urdf", "tool0"),
    ("UR10 on a 1.5-m stand", "ur_description/urdf/ur10_robot.urdf", "tool0"),
    ("xArm7", "xarm_description/urdf/xarm7.urdf", "link_eef"),
    ("Kinova Jaco2", "kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
    ("Unitree Z1", "z1_description/urdf/z1.urdf", "gripperMover"),
    ("SO-100", "so_arm_description/urdf/so100.urdf", "gripper"),
    ("double pendulum", "double_pendulum_description/urdf/double_pendulum.urdf", "link2"),
]
EXPECT = {"tracking_rms_deg": {"lt": 1.0}, "task_complete": {"eq": 1}}


def load(section: dict):
    """The robot's model, as a run builds it."""
    import numpy as np

    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry

    info = default_registry().get("robot", "urdf")
    return info.factory(info.config.model_validate(section), Context(Path.cwd(), np.random.default_rng(0), 0.001)).model


def posture(model, fraction: float) -> list[float]:
    """The posture at ``fraction`` of each joint's range, each joint in its own unit (degrees, or metres)."""
    import numpy as np

    q = model.limits.lower + fraction * (model.limits.upper - model.limits.lower)
    return [round(float(np.degrees(v) if turns else v), 4) for v, turns in zip(q, model.revolute)]


def run_one(name: str, rel: str, ee: str, keep: Path | None) -> str:
    urdf = ERD / rel
    root = ET.parse(urdf).getroot()
    robot = {"type": "urdf", "file": f"package://example-robot-data/robots/{rel}", "ee_frame": ee}
    if "stand" in name:  # (on the floor, the move passes through postures where the wrist hits it)
        robot["base"] = {"position": [0.0, 0.0, 1.5]}
    limits = {}
    for j in root.iter("joint"):  # a continuous joint, or one whose file gives no range and no effort (the pendulum)
        lim = j.find("limit")
        if j.get("type") not in ("revolute", "continuous", "prismatic"):
            continue
        empty = lim is not None and float(lim.get("upper", 0)) <= float(lim.get("lower", 0))
        if j.get("type") == "continuous" or empty:
            limits[j.get("name")] = {"range_deg": [-180, 180]}
        if lim is not None and float(lim.get("effort", 1)) <= 0:
            limits[j.get("name")] |= {"effort": 5.0, "velocity_deg_s": 360.0}
    if limits:
        robot["limits"] = limits
    model = load(robot)
    n, prismatic = model.dof, int((~model.revolute).sum())
    d, f = (np.asarray(getattr(model.pin_model, k)) for k in ("damping", "friction"))  # (as the file declares)
    dyn = " / ".join(f"{v.min():g}" if v.min() == v.max() else f"{v.min():g}–{v.max():g}" for v in (d, f))
    folder = keep or Path(tempfile.mkdtemp())
    scenario = folder / f"{name.lower().replace(' ', '_').replace('-', '')}.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": scenario.stem, "robot": robot,
        "planner": {"type": "multi-cubic", "segment_durations": [3.0]},
        "controller": {"type": "joint-pd", "gains": "auto"},  # (its feedforward: inverse-dynamics, the default)
        "task": {"targets": [{"name": "A", "joints": posture(model, 0.4)},
                             {"name": "B", "joints": posture(model, 0.6)}]},
        "duration": 4.0, "expect": EXPECT}, sort_keys=False))
    env = {**os.environ, "MUJOCO_GL": "egl"}
    cli = [sys.executable, "-m", "rehabkit.cli"]
    check = subprocess.run([*cli, "validate", str(scenario)], capture_output=True, text=True, env=env)
    out = folder / "out"
    done = subprocess.run([*cli, "run", str(scenario), "--out", str(out)], capture_output=True, text=True, env=env)
    row = f"| {name} | {n}{f' ({prismatic} prismatic)' if prismatic else ''} | {dyn} | "
    summary = out / "summary.json"
    if not summary.exists():
        why = (done.stderr or done.stdout).strip().splitlines()
        return row + f"– | validate {check.returncode}, run {done.returncode}: {why[-1][:160] if why else '?'} |"
    s = json.loads(summary.read_text())
    m = s["metrics"]
    verdicts = ", ".join(f"{e['metric']} {'pass' if e['passed'] else 'FAIL'}" for e in s["expectations"])
    said = [x.strip() for x in (check.stdout + check.stderr).splitlines() if x.strip().startswith("PLAN")]
    if why := s.get("tracking"):  # (the run's own account of its worst joint, where it tracked badly)
        said.append(f"TRACKING {why['joint']}: {'; '.join(why['causes'])}")
    safety = "; ".join(e["message"][:110] for e in s["safety"]["events"]) or "none"
    contact = m.get("contact_steps") or 0
    saturated = m.get("torque_saturation_steps") or 0
    return (row + f"{m['tracking_rms_deg']:.3f} / {m['tracking_max_deg']:.2f} | {verdicts} | "
            f"{safety} | {contact} / {saturated} | {'; '.join(said)[:300]} |")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--only", help="one robot, by its name in the table")
    parser.add_argument("--keep", type=Path, help="keep the scenarios and runs in this folder")
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print("| robot | joints | damping / friction declared | tracking rms / max [°] | expectations | safety events "
          "| contact / saturated steps | said |")
    print("|---|---|---|---|---|---|---|---|")
    for name, rel, ee in ROBOTS:
        if args.only and args.only.lower() not in name.lower():
            continue
        keep = None
        if args.keep:
            keep = args.keep / name.lower().replace(" ", "_")
            keep.mkdir(parents=True, exist_ok=True)
        print(run_one(name, rel, ee, keep), flush=True)
        if keep is None:
            shutil.rmtree(keep or "", ignore_errors=True)


if __name__ == "__main__":
    main()
