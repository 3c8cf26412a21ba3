"""MuJoCo simulation backend (registered through the ``rehabkit`` entry point like any plugin)."""

from __future__ import annotations

import copy
from typing import Literal

import mujoco
import numpy as np
from pydantic import ConfigDict, Field

from rehabkit.core.kinds.backend import EStopLatchedError
from rehabkit.core.kinds.capabilities import (
    BaseState,
    Cameras,
    Contacts,
    ExternalTorques,
    HeldObjects,
    HostsBodies,
    Instruments,
    NamedJoints,
    SceneGeometry,
    SceneObjects,
)
from rehabkit.core.kinds.interfaces import Backend, Contact, Context, StrictModel
from rehabkit.core.kinds.run_state import capture, restore
from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.safety.estop import RAMP_IN_AFTER_CLEAR_S, EStopLatch
from rehabkit.numerics.indices import span
from rehabkit.sim.loads import LoadApplier
from rehabkit.sim.scene import INTEGRATORS, InstrumentErrors, add_instruments, build_scene, couple_joints, engage_brakes
from rehabkit.sim.scene_view import SceneView


class MujocoConfig(StrictModel):
    """Physics settings."""

    # built where first used: the registry's model of the plugin (this one with its `type`), built as it is
    # registered, is what a scenario is validated with (~0.5 ms less of every run's start)
    model_config = ConfigDict(defer_build=True)

    timestep: float = Field(0.001, gt=0, le=0.01, description="physics step [s]")
    integrator: Literal[tuple(INTEGRATORS)] = "implicitfast"  # type: ignore[valid-type]


# the model's parameters that a run changes as it goes: a brake's friction and its constraint's softness
# (sim.scene.engage_brakes), a muscle's peak force under fatigue (the musculoskeletal patient), a grasp's weld (grasp)
RUN_MODEL_FIELDS = ("dof_frictionloss", "dof_solref", "dof_solimp", "actuator_gainprm", "eq_data")


class MujocoBackend(SceneView, Backend, Contacts, SceneGeometry, SceneObjects, HeldObjects, Cameras, Instruments,
                    BaseState, NamedJoints, ExternalTorques, HostsBodies):
    """MuJoCo physics: the robot's MJCF plus the scenario's world (and a simulated person's body, strapped in),
    driven by joint torques."""

    latch_name = "sim-{robot}"
    restorable = True
    RUN_STATE_NESTED = ("_errors",)  # (its noise stream: drawn from as the run goes)
    RUN_STATE_FIELDS = ("_errors", "_quiet_pairs", "ramp_in_after_clear")  # (the rest is its scene's wiring)

    def __init__(self, config: MujocoConfig, context: Context):
        robot = context.robot.model
        self.robot = robot
        self.timestep = config.timestep
        self.spec = build_scene(robot, context.world, config.timestep, config.integrator)
        add_instruments(self.spec, context.instruments)
        self.bodies = list(context.bodies)
        for body in self.bodies:
            body.compose(self.spec)
        self.model = self.spec.compile()
        self.data = mujoco.MjData(self.model)
        for body in self.bodies:
            body.bind(self.model, self.data)
        self.loads = LoadApplier(self.model, context.world.loads if context.world is not None else ())
        self._pushed = bool(self.loads)  # (asked each step: a plain attribute, not the applier's __bool__)
        self._errors = InstrumentErrors(context.instruments, context.seed or 0, rng=context.seeds.generator(
            InstrumentErrors.KEY) if context.seeds is not None else None)
        self._latch = EStopLatch.named(self.latch_name.format(robot=robot.name))  # (a rehearsal's latches as a robot's)
        self.ramp_in_after_clear = 0.0
        jids = [self.model.joint(name).id for name in robot.joint_names]
        self._q = span(np.array([self.model.jnt_qposadr[j] for j in jids]))
        self._v = span(np.array([self.model.jnt_dofadr[j] for j in jids]))
        self._friction = self.model.dof_frictionloss[self._v].copy()  # brakes off
        robot_bodies = {self.model.jnt_bodyid[j] for j in jids}
        # the fixed root and every body below it belong to the robot
        root = self.model.body(self.spec.worldbody.first_body().name).id
        self._robot_body = np.zeros(self.model.nbody, dtype=bool)
        for b in range(self.model.nbody):
            a = b
            while a != 0 and a != root:
                a = self.model.body_parentid[a]
            self._robot_body[b] = a == root or b in robot_bodies
        # contiguous joints: views into MjData stay valid for the whole run, so state() allocates nothing
        if isinstance(self._q, slice) and isinstance(self._v, slice):
            self._views = (self.data.qpos[self._q], self.data.qvel[self._v])
        else:
            self._views = None
        self._init_view(robot.ee_site)
        # feet on the floor hold the robot up: not collisions
        floor = [self.model.geom("floor").id] if context.world is None or context.world.floor else []
        self._support = np.zeros(self.model.ngeom, dtype=bool)
        self._support[[self.model.geom(g).id for g in robot.support_geoms]] = True
        self._floor = np.zeros(self.model.ngeom, dtype=bool)
        self._floor[floor] = True
        self._quiet_pairs = b""  # contact geom pairs last seen with nothing to count
        self._instruments: dict[str, slice] = {}
        self._root_joint = None
        if robot.floating:
            root_body = self.model.body(self.spec.worldbody.first_body().name)
            self._root_joint = int(self.model.body_jntadr[root_body.id])
            if self.model.jnt_type[self._root_joint] != mujoco.mjtJoint.mjJNT_FREE:
                raise ValueError(f"robot '{robot.name}' is floating but its root body has no free joint")
            j, m = self._root_joint, self.model
            self._root_at = (int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j]), int(m.jnt_bodyid[j]))
        # held objects: their weld to the holder, the holder site, the object's free joint
        self._held = {}
        for obj in (context.world.objects if context.world else []):
            if obj.held_by is not None:
                self._held[obj.name] = (self.model.equality(f"{obj.name}_hold").id, self.model.site(obj.held_by).id,
                                        self.model.joint(f"{obj.name}_free").id)

    def reset(self, q0: np.ndarray) -> None:
        if self._latch.latched() is not None:
            where = f"the simulated {self.robot.name}"
            raise EStopLatchedError(self._latch.refusal(where), self._latch.name, where)
        self.ramp_in_after_clear = RAMP_IN_AFTER_CLEAR_S if self._latch.take_ramp_in() else 0.0
        mujoco.mj_resetData(self.model, self.data)
        self.loads.reset()
        self.model.dof_frictionloss[self._v] = self._friction
        self.data.qpos[self._q] = q0
        couple_joints(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)
        for body in self.bodies:  # fitted to the robot where it now stands
            body.place()
            mujoco.mj_forward(self.model, self.data)
        for name in self._held:
            self.grasp(name)

    def grasp(self, name: str) -> None:
        eq, site, joint = self._held_entry(name)
        m, d = self.model, self.data
        qa, va = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
        mujoco.mj_kinematics(m, d)  # site positions of the present state (mj_step leaves those of the last one)
        d.qpos[qa : qa + 3] = d.site_xpos[site]
        d.qpos[qa + 3 : qa + 7] = [1.0, 0.0, 0.0, 0.0]
        d.qvel[va : va + 6] = 0.0
        mujoco.mj_forward(m, d)
        # weld at the present relative pose: the holder body as seen from the object
        obj_body, holder = m.eq_obj1id[eq], m.eq_obj2id[eq]
        rot = d.xmat[obj_body].reshape(3, 3)
        m.eq_data[eq, 0:3] = 0.0  # anchor at the holder's origin
        m.eq_data[eq, 3:6] = rot.T @ (d.xpos[holder] - d.xpos[obj_body])
        inv = np.zeros(4)
        mujoco.mju_negQuat(inv, d.xquat[obj_body])
        rel = np.zeros(4)
        mujoco.mju_mulQuat(rel, inv, d.xquat[holder])
        m.eq_data[eq, 6:10] = rel
        d.eq_active[eq] = 1

    def release(self, name: str) -> None:
        self.data.eq_active[self._held_entry(name)[0]] = 0

    def _held_entry(self, name: str):
        if name not in self._held:
            raise ValueError(f"'{name}' is not a held object; held: {', '.join(self._held) or 'none'}")
        return self._held[name]

    def state(self) -> tuple[float, np.ndarray, np.ndarray]:
        d = self.data
        if self._views is not None:
            return d.time, self._views[0], self._views[1]
        return d.time, d.qpos[self._q], d.qvel[self._v]

    def command(self, tau: np.ndarray) -> None:
        self.data.qfrc_applied[self._v] = tau

    def engage_brakes(self) -> bool:
        if self.robot.brakes is None:
            return False
        engage_brakes(self.model, self._v, self._friction + self.robot.brakes)
        return True

    def latch_estop(self, reason: str) -> bool:
        self._latch.press(reason, by="rehabkit (simulation)")
        return True

    def latched_estop(self) -> str | None:
        return self._latch.name if self._latch.latched() is not None else None

    def hosted(self) -> list:
        return self.bodies

    def external_torque(self, tau: np.ndarray) -> None:
        self.data.qfrc_applied[self._v] += tau  # on top of the command just sent

    def step(self, n: int = 1) -> None:
        if self._pushed:  # (held over the control period: a rig's push changes slowly)
            self.loads.apply(self.data, self.data.time)
        if n == 1:
            mujoco.mj_step(self.model, self.data)  # the nstep keyword alone costs ~0.5 us
        else:
            mujoco.mj_step(self.model, self.data, nstep=n)

    def contacts(self) -> list[Contact]:
        d, m = self.data, self.model
        n = d.ncon
        if n == 0:  # the common case, and slicing d.contact costs ~0.1 ms even when empty
            return []
        geoms = d.contact.geom[:n]
        pairs = geoms.tobytes()
        if pairs == self._quiet_pairs:  # the same geoms touching as last time, none of them counted (feet on the floor)
            return []
        robot = self._robot_body[m.geom_bodyid[geoms]]
        support = (self._support[geoms[:, 0]] & self._floor[geoms[:, 1]]) | (
            self._support[geoms[:, 1]] & self._floor[geoms[:, 0]])
        hits = np.flatnonzero((robot[:, 0] != robot[:, 1]) & ~support)
        self._quiet_pairs = b"" if len(hits) else pairs
        first = np.where(robot[:, 0], 0, 1)  # (the robot's geom first)
        return [Contact(self._geom_label(int(geoms[i, first[i]])), self._geom_label(int(geoms[i, 1 - first[i]])),
                        d.contact.pos[i].copy(), float(-d.contact.dist[i])) for i in hits]

    def _geom_label(self, g: int) -> str:
        """A geom's name, or its body's where it has none (a URDF's collision shapes are unnamed)."""
        m = self.model
        return m.geom(g).name or m.body(int(m.geom_bodyid[g])).name

    def base_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if self._root_joint is None:
            raise NotImplementedError(f"robot '{self.robot.name}' has no floating base to report")
        qa, va, body = self._root_at
        d = self.data
        rot = d.xmat[body].reshape(3, 3)
        # MuJoCo's free-joint angular velocity is in the body frame; report it in the world frame
        return d.qpos[qa : qa + 3].copy(), d.qpos[qa + 3 : qa + 7].copy(), d.qvel[va : va + 3].copy(), \
            rot @ d.qvel[va + 3 : va + 6]

    def read_instrument(self, name: str) -> np.ndarray:
        span = self._instruments.get(name)
        if span is None:  # looked up once: a by-name lookup costs a few us, read at the control rate
            s = self.model.sensor(name)
            span = self._instruments[name] = slice(int(s.adr[0]), int(s.adr[0] + s.dim[0]))
        return self._errors.apply(name, self.data.sensordata[span].copy())

    def run_state(self) -> tuple[dict, mujoco.MjData, dict[str, np.ndarray]]:
        """The scene's whole state (an ``MjData`` copy: the robot's, a person's body, objects, contacts, warm starts),
        the model's parameters a run changes (brakes' friction, muscles' fatigue) and the backend's own (held
        objects, the noise stream)."""
        return capture(self), copy.copy(self.data), {f: getattr(self.model, f).copy() for f in RUN_MODEL_FIELDS}

    def restore_run_state(self, state: tuple[dict, mujoco.MjData, dict[str, np.ndarray]]) -> None:
        own, data, params = state
        restore(self, own)  # (``data`` is the same object: its contents are put back in place, views stay valid)
        mujoco.mj_copyData(self.data, self.model, data)
        for name, values in params.items():
            getattr(self.model, name)[...] = values

    def close(self) -> None:
        self.close_view()


@hookimpl
def rehabkit_register_backends(registry) -> None:
    registry.add("mujoco", config=MujocoConfig, factory=MujocoBackend)
