"""The ARM keypad's motions: a held key as a ramped joint or Cartesian jog, fold/unfold as minimum-jerk moves.

Jogs ramp up while the key is held and down after its release, as the ARM limits
acceleration; they stop a little inside the hard joint limits so the servo never
leans on a stop. A Cartesian jog moves the gripper pose and follows it by the
robot's inverse kinematics, slowed where a joint would pass its speed limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rehabkit.trajectories import quintic

AXES = {"x": 0, "y": 1, "z": 2, "roll": 0, "pitch": 1, "yaw": 2}
SOFT_LIMIT_FRACTION = 0.002
JOINT_SPEED_FRACTION = 0.9  # Cartesian jogs slow down so no joint passes this share of its speed limit


@dataclass
class Jog:
    key: str
    release_at: float
    factor: float = 0.0
    pose: np.ndarray | None = None  # Cartesian jogs: the gripper pose being moved


class Quintic:
    """Rest-to-rest joint motion with a minimum-jerk profile."""

    def __init__(self, q0: np.ndarray, q1: np.ndarray, duration: float):
        self.q0, self.dq, self.duration = q0, q1 - q0, max(duration, 1e-3)

    def sample(self, t):
        s, ds, dds = (w[:, None] for w in quintic(np.atleast_1d(t) / self.duration))
        return self.q0 + s * self.dq, ds / self.duration * self.dq, dds / self.duration**2 * self.dq


class Jogger:
    """The next joint reference of a jog (``config``: the keypad's jog speeds and ramp)."""

    def __init__(self, robot, config):
        self.robot, self.config = robot, config
        self.velocity = robot.model.limits.velocity
        lim = robot.model.limits
        inset = SOFT_LIMIT_FRACTION * (lim.upper - lim.lower)
        self.soft_lower, self.soft_upper = lim.lower + inset, lim.upper - inset

    def start(self, key: str, release_at: float, q_ref: np.ndarray) -> Jog:
        return Jog(key, release_at, pose=self.robot.fk(q_ref) if key[:-1] in AXES else None)

    def advance(self, jog: Jog, t: float, dt: float, q_ref: np.ndarray) -> np.ndarray | None:
        """The reference one step on; ``None`` once the jog has ramped down, ``q_ref`` itself if it is blocked
        (reach, joint limit or singularity)."""
        cfg, robot = self.config, self.robot
        rate = dt / cfg.ramp_s
        jog.factor = min(1.0, jog.factor + rate) if t < jog.release_at else jog.factor - rate
        if jog.factor <= 0:
            return None
        name, sign = jog.key[:-1], (1.0 if jog.key[-1] == "+" else -1.0)
        new = q_ref.copy()
        if jog.key in ("open", "close") or name == "lift" or name.startswith("j"):
            if jog.key in ("open", "close"):
                j, sign = robot.gripper_index, (1.0 if jog.key == "open" else -1.0)
            else:
                j = robot.lift_index if name == "lift" else robot.arm.start + int(name[1:]) - 1
            new[j] += sign * jog.factor * cfg.jog_joint_fraction * self.velocity[j] * dt
        else:
            new = self._cartesian_step(jog, name, sign, dt, q_ref)
            if new is None:
                return q_ref
        return np.clip(new, self.soft_lower, self.soft_upper)

    def _cartesian_step(self, jog: Jog, name: str, sign: float, dt: float, q_ref: np.ndarray) -> np.ndarray | None:
        cap = self.velocity * dt * JOINT_SPEED_FRACTION
        scale = 1.0
        for _ in range(3):  # the joint step is nearly linear in the Cartesian step: rescale, check again
            pose = jog.pose.copy()
            amount = sign * jog.factor * scale * dt
            if name in ("x", "y", "z"):
                pose[AXES[name], 3] += amount * self.config.jog_speed_m_s
            else:
                turn = np.zeros(3)
                turn[AXES[name]] = amount * np.radians(self.config.jog_turn_deg_s)
                pose[:3, :3] = pose[:3, :3] @ Rotation.from_rotvec(turn).as_matrix()
            sols = self.robot.ik(pose, reference=q_ref)
            if not sols:
                return None
            ratio = float(np.max(np.abs(sols[0] - q_ref) / cap))
            if ratio <= 1.0:
                jog.pose = pose
                return sols[0]
            if ratio > 50.0:  # a branch jump, not a slow joint: a singularity or the edge of the workspace
                return None
            scale /= ratio * 1.02
        return None
