"""What a bridge drives: the :class:`Plant` interface real drives implement, and :class:`MujocoPlant`, the robot's
MuJoCo model standing in for them (tests, hardware-in-the-loop rehearsal)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import mujoco
import numpy as np

from rehabkit.core.kinds.capabilities import PassiveJoints
from rehabkit.core.kinds.sensor import INSTRUMENT_DIM, Instrument
from rehabkit.core.scenario.loads import Load
from rehabkit.core.scenario.models import World
from rehabkit.sim.loads import LoadApplier
from rehabkit.sim.scene import InstrumentErrors, add_instruments, build_scene, couple_joints, engage_brakes
from rehabkit.sim.scene_view import measured_joints


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

    def read_instruments(self) -> np.ndarray:
        """The instruments' readings (force-torque sensors, accelerometers: 3 values each), in the order the host's
        run declares them; default none."""
        return np.zeros(0)

    def brake(self) -> bool:
        """Apply the holding brakes; False without any (the default)."""
        return False

    def joint_inertia(self) -> np.ndarray | None:
        """Each joint's own inertia where the robot is now [kg·m², or kg for a sliding joint], or None if unknown
        (the default: the bridge's hold then takes its gains as they are)."""
        return None

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
    """A robot's MuJoCo model as the plant (the robot alone on the floor), with the run's instruments (and their
    simulated errors) and a test rig's loads."""

    def __init__(self, robot, timestep: float = 0.001, instruments: Sequence[Instrument] = (),
                 loads: Sequence[Load] = (), seed: int = 0):
        self.robot, self.timestep = robot, timestep
        spec = build_scene(robot.model, World(), timestep)
        add_instruments(spec, instruments)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.loads = LoadApplier(self.model, loads)
        self._errors = InstrumentErrors(instruments, seed)
        self._readings = [(i.name, slice(int(self.model.sensor(i.name).adr[0]),
                                         int(self.model.sensor(i.name).adr[0]) + INSTRUMENT_DIM)) for i in instruments]
        self._values = np.zeros(INSTRUMENT_DIM * len(instruments))
        ids = [self.model.joint(n).id for n in robot.model.joint_names]
        self._q = np.array([self.model.jnt_qposadr[j] for j in ids])
        self._v = np.array([self.model.jnt_dofadr[j] for j in ids])
        self.joints, self.effort = len(ids), robot.model.limits.effort
        self._m = measured_joints(self.model, robot.model)
        self._friction = self.model.dof_frictionloss[self._v].copy()

    def brake(self, joints=None):
        """The holding brakes on (``joints``: those joints' only; default all)."""
        if self.robot.model.brakes is None:
            return False
        at = slice(None) if joints is None else np.asarray(joints, int)
        engage_brakes(self.model, self._v[at], self._friction[at] + self.robot.model.brakes[at])
        return True

    def reset(self, q0):
        mujoco.mj_resetData(self.model, self.data)
        self.loads.reset()
        self.model.dof_frictionloss[self._v] = self._friction
        self.data.qpos[self._q] = q0
        if isinstance(self.robot, PassiveJoints):  # a parallel mechanism: its passive joints close the loops
            for name, value in self.robot.passive_state(q0).items():
                adr = self.model.jnt_qposadr[self.model.joint(name).id]
                value = np.atleast_1d(value)
                self.data.qpos[adr : adr + len(value)] = value
        couple_joints(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)

    def read(self):
        return self.data.qpos[self._q].copy(), self.data.qvel[self._v].copy()

    def read_measured(self):
        return self.data.qpos[self._m]

    def read_instruments(self):
        out, data = self._values, self.data.sensordata
        for k, (name, at) in enumerate(self._readings):
            out[INSTRUMENT_DIM * k : INSTRUMENT_DIM * (k + 1)] = self._errors.apply(name, data[at].copy())
        return out

    def apply(self, tau):
        self.data.qfrc_applied[self._v] = tau

    def advance(self):
        if self.loads:
            self.loads.apply(self.data, self.data.time)
        mujoco.mj_step(self.model, self.data)

    def gravity(self, q):
        return self.robot.gravity_torque(q)

    def joint_inertia(self) -> np.ndarray:
        """Each joint's own inertia where the plant is now (the mass matrix's diagonal with the rotors' armature)
        [kg·m², or kg for a sliding joint]: what a drive's auto-tuning finds."""
        full = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, full)
        return full[self._v, self._v] + self.model.dof_armature[self._v]
