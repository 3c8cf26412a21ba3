"""Exact Dynamics ARM (MANUS), the wheelchair-mounted assistive manipulator (after Stuyt et al.).

Kinematics: a PUMA-like modified-DH chain (Craig: α_{i-1}, a_{i-1}, d_i) from
public MANUS control code, in millimetres:

    1:   0°,   0,     0        4: +90°,   0,   323.4
    2: −90°,   0,     0        5: −90°,   0,     0
    3:   0°, 396.7,  99.2      6: +90°,   0,     0

Frame 6 is at the wrist centre; q3 = 0 holds the forearm perpendicular to the
upper arm; the forearm is a 27.5 mm-radius cylinder. A gripper of ``gripper``
length extends along the last axis. Inverse kinematics keeps the elbow up,
as the ARM's controller does. The optional lift and the gripper fingers are
not modelled yet.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import yaml
from pydantic import Field
from scipy.optimize import least_squares

from rehabkit import hookimpl
from rehabkit.core.interfaces import Context, Robot, StrictModel
from rehabkit.models.dh import DHRobotSpec, DHRowSpec, JointSpec, PoseSpec, build_dh_robot
from rehabkit.models.robot_model import SafeStop

TABLE_MM = [(0, 0, 0), (-90, 0, 0), (0, 396.7, 99.2), (90, 0, 323.4), (-90, 0, 0), (90, 0, 0)]


class ArmConfig(StrictModel):
    """Placement beside the wheelchair and gripper length."""

    gripper: float = Field(0.12, gt=0, description="wrist centre to gripper tip [m]")
    base: PoseSpec = Field(PoseSpec(position=(0.0, 0.0, 0.7)), description="arm base, beside the wheelchair seat")
    safe_stop: SafeStop = "hold"


class ArmRobot(Robot):
    """Exact Dynamics ARM: 6-DoF PUMA-like wheelchair-mounted arm (MDH from MANUS code), elbow-up IK."""

    def __init__(self, config: ArmConfig, context: Context | None = None):
        text = resources.files(__package__).joinpath("arm_joints.yaml").read_text()
        joints = [JointSpec.model_validate(j) for j in yaml.safe_load(text)["joints"]]
        table = [DHRowSpec(a=a / 1000, alpha_deg=alpha, d=d / 1000) for alpha, a, d in TABLE_MM]
        self.spec = DHRobotSpec(name="arm", convention="modified", table=table, joints=joints,
                                tool=PoseSpec(position=(0.0, 0.0, config.gripper)), base=config.base,
                                safe_stop=config.safe_stop)
        self.model = build_dh_robot(self.spec)
        self.chain = self.spec.chain()
        self.config = config

    def fk(self, q: np.ndarray) -> np.ndarray:
        return self.chain.fk(np.asarray(q, float))

    def elbow_up(self, q: np.ndarray) -> bool:
        """Whether the elbow sits above the shoulder-wrist line."""
        frames = self.chain.frames(q)
        shoulder, elbow, wrist = frames[1][:3, 3], frames[2][:3, 3], frames[5][:3, 3]
        line = wrist - shoulder
        s = np.clip((elbow - shoulder) @ line / (line @ line), 0.0, 1.0)
        return bool(elbow[2] > shoulder[2] + s * line[2])

    def ik(self, pose: np.ndarray) -> list[np.ndarray]:
        """Joint solutions (elbow up) reaching ``pose``, numerically from several starts."""
        pose = np.asarray(pose, float)
        lim = self.model.limits

        def error(q):
            t = self.fk(q)
            return np.concatenate([t[:3, 3] - pose[:3, 3], 0.2 * (t[:3, :3] - pose[:3, :3]).ravel()])

        found: list[np.ndarray] = []
        # shoulder angle in closed form from the wrist centre and the 99.2 mm shoulder offset (two branches,
        # and their half-turns); the rest from typical elbow-up arm and wrist postures
        wrist = pose[:3, 3] - self.config.gripper * pose[:3, 2]
        r, offset = np.hypot(wrist[0], wrist[1]), TABLE_MM[2][2] / 1000
        phi = np.arctan2(wrist[1], wrist[0])
        lean = np.arcsin(np.clip(offset / max(r, offset), -1.0, 1.0))
        shoulders = [phi - lean, phi + lean - np.pi, phi + lean, phi - lean + np.pi]
        arms = [np.radians(a) for a in ([-60, 30, 0, 60, 0], [-120, 60, 0, 60, 0], [-60, 30, 90, -60, 90],
                                        [-120, 60, 90, -60, 90])]
        starts = [np.clip(np.concatenate([[(s + np.pi) % (2 * np.pi) - np.pi], a]), lim.lower, lim.upper)
                  for s in shoulders for a in arms]
        for start in starts:
            sol = least_squares(error, start, bounds=(lim.lower, lim.upper), xtol=1e-14, ftol=1e-14, gtol=1e-14)
            new = all(np.abs(sol.x - f).max() > 1e-6 for f in found)
            if np.abs(sol.fun).max() < 1e-9 and self.elbow_up(sol.x) and new:
                found.append(sol.x)
        return found


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("arm", config=ArmConfig, factory=ArmRobot)
