"""Robots from ROS description packages as they ship (example-robot-data from PyPI, found through AMENT_PREFIX_PATH,
and the test package of our own with xacro and COLLADA): for each, its joints and meshes, ``validate`` and ``run``
exit codes (a joint-space move between two postures inside its limits), Pinocchio against MuJoCo (end-effector
distance, the largest over 1,000 random postures; total mass), and the load time the first time (xacro expanded,
COLLADA converted) and from the cache.

    python benchmarks/description_packages.py
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
ERD = Path(__import__("cmeel").__file__).parent.parent / "cmeel.prefix"
ROBOTS = ERD / "share" / "example-robot-data" / "robots"
OWN = ROOT / "tests" / "data" / "rehab_arm_description"


def _urdf(file: Path, ee: str, **more) -> dict:
    return {"type": "urdf", "file": str(file), "ee_frame": ee, **more}


CASES = [  # (name, kind, the robot section)
    ("rehab_arm (our package)", "2-link arm, xacro",
     _urdf(OWN / "urdf" / "arm.urdf.xacro", "hand", packages=[str(OWN)], xacro_args={"upper_length": "0.32"})),
    ("UR5", "industrial arm", _urdf(ROBOTS / "ur_description/urdf/ur5_robot.urdf", "tool0")),
    ("Panda", "arm + gripper", _urdf(ROBOTS / "panda_description/urdf/panda.urdf", "panda_hand_tcp")),
    ("Kinova Jaco2", "assistive arm (wheelchair)",
     _urdf(ROBOTS / "kinova_description/robots/kinova.urdf", "j2s6s200_end_effector")),
    ("Unitree Z1", "arm", _urdf(ROBOTS / "z1_description/urdf/z1.urdf", "gripperMover")),
    ("Solo12", "quadruped, fixed base", _urdf(ROBOTS / "solo_description/robots/solo12.urdf", "FL_FOOT")),
    ("Solo12", "quadruped, floating on its feet",
     _urdf(ROBOTS / "solo_description/robots/solo12.urdf", "FL_FOOT", floating=True,
           feet=["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"], base={"position": [0, 0, 0.235]})),
]
# a floating robot moves between postures it can stand in (its SRDF's standing, and a crouch), not anywhere in range
STANDING = {"Solo12": ([0.1, 0.8, -1.6, -0.1, 0.8, -1.6, 0.1, -0.8, 1.6, -0.1, -0.8, 1.6],
                       [0.1, 1.0, -2.0, -0.1, 1.0, -2.0, 0.1, -1.0, 2.0, -0.1, -1.0, 2.0])}


def meshes(path: Path) -> str:
    text = path.read_text()
    counts = {ext: text.count(f".{ext}\"") for ext in ("dae", "stl", "obj")}
    return ", ".join(f"{n} .{ext}" for ext, n in counts.items() if n) or "none"


def main() -> None:
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry
    from tests.test_description_packages import _agreement

    os.environ["AMENT_PREFIX_PATH"] = str(ERD)
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print("| robot | kind | joints | meshes | xacro | validate | run | FK Pinocchio vs MuJoCo, max of 1000 [m] | "
          "mass difference [kg] | load, first / cached [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    registry = default_registry()
    for name, kind, section in CASES:
        import xml.etree.ElementTree as ET

        if section["file"].endswith(".urdf"):  # continuous joints get a range here (the scenario's limits)
            spinning = [j.get("name") for j in ET.parse(section["file"]).getroot().iter("joint")
                        if j.get("type") == "continuous"]
            section = {**section, "limits": {j: {"range_deg": [-180, 180]} for j in spinning}}
        cache = Path(tempfile.mkdtemp())
        os.environ["REHABKIT_CACHE"] = str(cache)
        info = registry.get("robot", "urdf")
        config = info.config.model_validate(section)
        context = Context(Path.cwd(), np.random.default_rng(0), 0.001)
        t = time.perf_counter()
        robot = info.factory(config, context)
        first = time.perf_counter() - t
        t = time.perf_counter()
        info.factory(config, context)
        cached = time.perf_counter() - t
        distance, mass = _agreement(robot)
        lim = robot.model.limits
        span = lim.upper - lim.lower  # (a move the plan makes within the speed limits: a cubic peaks at 1.5 × mean)
        a = lim.lower + 0.3 * span
        b = a + np.minimum(0.3 * span, 0.5 * lim.velocity * 2.0 / 1.5)
        if section.get("floating"):
            a, b = (np.array(p) for p in STANDING[name])
        n = robot.model.dof
        from rehabkit.core.safety.stopping import joint_inertia

        inertia = joint_inertia(robot.model, a)  # (gains critically damped at 20 rad/s on each joint's inertia)
        kp, kd = (400 * inertia).tolist(), (40 * inertia).tolist()
        folder = Path(tempfile.mkdtemp())
        (folder / "s.yaml").write_text(yaml.safe_dump({
            "name": name.split()[0].lower(), "robot": section,
            "planner": {"type": "multi-cubic", "segment_durations": [2.0]},
            "controller": {"type": "joint-pd", "kp": kp, "kd": kd, "feedforward": "inverse-dynamics"},
            "task": {"targets": [{"name": "A", "joints_deg": np.degrees(a).tolist()},
                                 {"name": "B", "joints_deg": np.degrees(b).tolist()}]}, "duration": 2.5}))
        env = {**os.environ}
        commands = (["validate"], ["run", "--out", str(folder / "out")])
        done = [subprocess.run([sys.executable, "-m", "rehabkit.cli", *cmd, str(folder / "s.yaml")], env=env,
                               capture_output=True, text=True) for cmd in commands]
        codes = [d.returncode for d in done]
        for d in done:
            if d.returncode:
                why = [x for x in (d.stderr + d.stdout).splitlines() if "SAFETY" in x or "FAIL" in x or ":" in x]
                print(f"  ({name}: {(why or ['?'])[0].strip()[:200]})", file=sys.stderr)
        print(f"| {name} | {kind} | {n} | {meshes(Path(section['file']))} | "
              f"{'yes' if section['file'].endswith('.xacro') else 'no'} | {codes[0]} | {codes[1]} | {distance:.1e} | "
              f"{mass:.1e} | {first:.2f} / {cached:.2f} |", flush=True)
        shutil.rmtree(cache, ignore_errors=True)
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
