"""What a bridge drives: the :class:`Plant` interface real drives implement, and :class:`MujocoPlant`, the robot's
MuJoCo model standing in for them (tests, hardware-in-the-loop rehearsal)."""

from __future__ import annotations

from abc import ABC, abstractmethod

import mujoco
import numpy as np

from rehabkit.core.backends.scene import build_scene
from rehabkit.core.backends.scene_view import measured_joints
from rehabkit.core.capabilities import PassiveJoints
from rehabkit.core.scenario.models import World


class Plant(ABC):
    """What a bridge drives: real drives, or a simulation standing in for them."""

    joints: int
    timestep: float
    effort: np.ndarray

    @abstractmethod
    def reset(self, q0: np.ndarray) -> None:
        """Bring the robot to rest at ``q0`` (a simulation jumps there; drives would move)."""

    @abstractmethod
    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint positions and velocities."""

    def read_measured(self) -> np.ndarray:
        """Positions of measured-only joints (passive, with an encoder), in the robot's order; default none."""
        return np.zeros(0)

    @abstractmethod
    def apply(self, tau: np.ndarray) -> None:
        """Joint torques until the next call."""

    @abstractmethod
    def advance(self) -> None:
        """One tick of the plant (a simulation steps; drives just run)."""

    @abstractmethod
    def gravity(self, q: np.ndarray) -> np.ndarray:
        """Torques holding the robot still at ``q``."""


class MujocoPlant(Plant):
    """A robot's MuJoCo model as the plant (the robot alone on the floor)."""

    def __init__(self, robot, timestep: float = 0.001):
        self.robot, self.timestep = robot, timestep
        self.model = build_scene(robot.model, World(), timestep).compile()
        self.data = mujoco.MjData(self.model)
        ids = [self.model.joint(n).id for n in robot.model.joint_names]
        self._q = np.array([self.model.jnt_qposadr[j] for j in ids])
        self._v = np.array([self.model.jnt_dofadr[j] for j in ids])
        self.joints, self.effort = len(ids), robot.model.limits.effort
        self._m = measured_joints(self.model, robot.model)

    def reset(self, q0):
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self._q] = q0
        if isinstance(self.robot, PassiveJoints):  # a parallel mechanism: its passive joints close the loops
            for name, value in self.robot.passive_state(q0).items():
                adr = self.model.jnt_qposadr[self.model.joint(name).id]
                value = np.atleast_1d(value)
                self.data.qpos[adr : adr + len(value)] = value
        mujoco.mj_forward(self.model, self.data)

    def read(self):
        return self.data.qpos[self._q].copy(), self.data.qvel[self._v].copy()

    def read_measured(self):
        return self.data.qpos[self._m]

    def apply(self, tau):
        self.data.qfrc_applied[self._v] = tau

    def advance(self):
        mujoco.mj_step(self.model, self.data)

    def gravity(self, q):
        return self.robot.gravity_torque(q)
