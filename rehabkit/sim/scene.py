"""Compose the simulated scene: the robot's MJCF placed at its base, plus the world."""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.core.scenario.models import World
from rehabkit.models.chain import matrix_to_quat_wxyz, rpy_to_matrix
from rehabkit.models.robot_model import RobotModel

_SHAPES = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
           "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}
INTEGRATORS = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST, "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
               "euler": mujoco.mjtIntegrator.mjINT_EULER, "rk4": mujoco.mjtIntegrator.mjINT_RK4}


HELD_TYPE = 2  # collision bit of objects the robot carries
WORLD_AFFINITY = 1 | HELD_TYPE  # the floor and obstacles meet the robot (bit 1) and carried objects (bit 2)


def _size3(size: list[float]) -> list[float]:
    return [*size, *([0.0] * (3 - len(size)))]


def camera_axes(cam) -> np.ndarray:
    """World rotation of a MuJoCo camera (it looks along its -z, +y up in the image) aimed at ``look_at``."""
    back = np.asarray(cam.position, float) - np.asarray(cam.look_at, float)
    z = back / np.linalg.norm(back)
    x = np.cross(np.asarray(cam.up, float), z)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"camera '{cam.name}': 'up' is parallel to the viewing direction")
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


_INSTRUMENTS = {"accelerometer": mujoco.mjtSensor.mjSENS_ACCELEROMETER, "gyro": mujoco.mjtSensor.mjSENS_GYRO,
                "force": mujoco.mjtSensor.mjSENS_FORCE, "torque": mujoco.mjtSensor.mjSENS_TORQUE}
MOUNT_KG = 0.001  # a force sensor's mount: light, so the sensor reads what pushes on it, not its inertia


def add_instruments(spec: mujoco.MjSpec, instruments) -> None:
    """A site (axes of its body) and a MuJoCo sensor on it for each instrument; a force sensor's site on its mount,
    a light body beyond it (MuJoCo's force and torque sensors read what the body of their site exerts on its
    parent)."""
    for ins in instruments:
        body = spec.body(ins.body)
        if body is None:
            names = sorted(b.name for b in spec.bodies if b.name)
            raise ValueError(f"instrument '{ins.name}': no body '{ins.body}' in the scene; bodies: {', '.join(names)}")
        if ins.mount is not None:
            mount = spec.body(ins.mount)
            if mount is None:
                # (ipos given: left out, MjSpec put the centre of mass as far again beyond the mount, where a
                # test rig's push, applied at it, had a longer lever than the sensor it loads)
                mount = body.add_body(name=ins.mount, pos=ins.position, ipos=[0.0, 0.0, 0.0], mass=MOUNT_KG,
                                      inertia=[1e-7, 1e-7, 1e-7], explicitinertial=True)
            site = mount.add_site(name=f"{ins.name}_site", size=[0.006, 0, 0], rgba=[0.9, 0.6, 0.1, 1])
        else:
            site = body.add_site(name=f"{ins.name}_site", pos=ins.position, size=[0.006, 0, 0], rgba=[0.1, 0.8, 0.1, 1])
        spec.add_sensor(name=ins.name, type=_INSTRUMENTS[ins.kind], objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname=site.name)


class InstrumentErrors:
    """A simulated sensor's imperfections (each instrument's bias and white noise), from its own seeded stream."""

    KEY = 0x5E45  # its stream's key beside the seed
    RUN_STATE_FIELDS = ("rng",)  # (a session snapshot takes its stream)

    def __init__(self, instruments, seed: int = 0, rng: np.random.Generator | None = None):
        self.bias = {i.name: np.asarray(i.bias, float) for i in instruments if i.simulated_error}
        self.noise = {i.name: i.noise for i in instruments if i.simulated_error}
        self.rng = rng if rng is not None else np.random.default_rng([seed, self.KEY])

    def apply(self, name: str, value: np.ndarray) -> np.ndarray:
        bias = self.bias.get(name)
        if bias is None:
            return value
        value += bias
        if self.noise[name]:
            value += self.rng.normal(0.0, self.noise[name], value.shape)
        return value


def couple_joints(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Joints coupled to others (a URDF's ``<mimic>``: MuJoCo's joint equalities) put where their coupling says,
    ``q1 = c0 + c1·q2 + c2·q2² + …``: a reset starts them satisfied, not pulled there by the constraint."""
    for e in range(model.neq):
        if model.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or model.eq_obj2id[e] < 0:
            continue
        follower, leader = model.jnt_qposadr[model.eq_obj1id[e]], model.jnt_qposadr[model.eq_obj2id[e]]
        c, x = model.eq_data[e, :5], data.qpos[leader]
        data.qpos[follower] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3 + c[4] * x**4


def engage_brakes(model: mujoco.MjModel, dofs, torque: np.ndarray) -> None:
    """Holding brakes on ``dofs``: dry friction up to ``torque`` (MuJoCo's friction loss, solved with the
    constraints), made hard — MuJoCo's default softness lets a loaded joint creep at degrees per second."""
    model.dof_frictionloss[dofs] = torque
    model.dof_solref[dofs] = [2 * model.opt.timestep, 1.0]
    model.dof_solimp[dofs, :3] = [0.99, 0.999, 0.001]


DEFAULT_SOLREF = (0.02, 1.0)  # MuJoCo's own, which a file that chose no softness for its joints' friction has
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
DRY = (0.9999, 0.9999, 0.001, 0.5, 2.0)  # MuJoCo's hardest impedance


def dry_friction(spec: mujoco.MjSpec, timestep: float) -> list[str]:
    """Make each joint's declared Coulomb friction (MuJoCo's ``frictionloss``, a URDF's ``<dynamics friction>``)
    dry, as declared: under MuJoCo's default softness a joint held by less torque than its friction creeps at
    ``r·τ / (m·b)`` (r = 0.11, b = 105 /s), about 7 rad/s on the 1.4e-4 kg·m² wrist of an xArm7 that declares 1 N·m
    — friction a light joint then barely has, while the controllers' model says it has all of it. At the hardest
    impedance and a two-step time constant it creeps at 0.04 °/s. A joint whose file chose its own softness
    (``solreffriction``/``solimpfriction``) keeps it. Returns the joints changed."""
    changed = []
    for joint in spec.joints:
        if joint.frictionloss > 0 and np.allclose(joint.solref_friction, DEFAULT_SOLREF) \
                and np.allclose(joint.solimp_friction, DEFAULT_SOLIMP):
            joint.solref_friction = [2 * timestep, 1.0]
            joint.solimp_friction = list(DRY)
            changed.append(joint.name)
    return changed


def build_scene(robot: RobotModel, world: World, timestep: float, integrator: str = "implicitfast") -> mujoco.MjSpec:
    """An MjSpec with the robot (torque-driven: its own actuators removed) and the world objects.

    World geoms collide with the robot and with free objects; the robot does not
    collide with itself (its generated links overlap at the joints by design).
    """
    spec = mujoco.MjSpec.from_string(robot.mjcf)
    for actuator in list(spec.actuators):
        spec.delete(actuator)  # rehabkit applies joint torques after the safety layer
    root = spec.worldbody.first_body()
    root.pos = robot.base_pose[:3, 3]
    root.quat = matrix_to_quat_wxyz(robot.base_pose[:3, :3])
    spec.option.timestep = timestep
    spec.option.integrator = INTEGRATORS[integrator]
    spec.option.gravity = robot.gravity
    dry_friction(spec, timestep)
    spec.visual.global_.offwidth, spec.visual.global_.offheight = 1920, 1440  # room for camera sensors
    # a 1024² shadow map instead of MuJoCo's 4096²: the same frames to 0.02 grey levels on average, at less than
    # half the cost on a CPU renderer, where the shadow pass is most of a frame
    spec.visual.quality.shadowsize = 1024
    spec.worldbody.add_light(name="key_light", pos=[0, -1.0, 3.0], dir=[0, 0.3, -1], diffuse=[0.8, 0.8, 0.8])
    if world.floor:
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3, 3, 0.05],
                                contype=0, conaffinity=WORLD_AFFINITY, rgba=[0.85, 0.85, 0.82, 1])
    for cam in world.cameras:
        spec.worldbody.add_camera(name=cam.name, pos=cam.position, quat=matrix_to_quat_wxyz(camera_axes(cam)),
                                  fovy=cam.fovy_deg)
    for obj in world.objects:
        # matte (no highlight washing out the colour), optionally self-lit like a fluorescent target
        spec.add_material(name=f"{obj.name}_material", specular=0.0, shininess=0.0, reflectance=0.0,
                          emission=obj.emission)
        quat = matrix_to_quat_wxyz(rpy_to_matrix(np.radians(obj.pose.rpy_deg)))
        geom = dict(name=obj.name, type=_SHAPES[obj.shape], size=_size3(obj.size), rgba=list(obj.rgba),
                    material=f"{obj.name}_material")
        if obj.mocap:  # kinematic: moved by events, touches nothing
            body = spec.worldbody.add_body(name=obj.name, pos=obj.pose.position, quat=quat, mocap=True)
            body.add_geom(**geom, contype=0, conaffinity=0)
        elif obj.dynamic:  # free: collides with the robot and the world
            body = spec.worldbody.add_body(name=obj.name, pos=obj.pose.position, quat=quat)
            body.add_freejoint(name=f"{obj.name}_free")
            if obj.held_by is None:
                body.add_geom(**geom, mass=obj.mass, contype=1, conaffinity=1)
            else:  # carried by the robot: touches the world, never the hand holding it
                body.add_geom(**geom, mass=obj.mass, contype=HELD_TYPE, conaffinity=HELD_TYPE)
                holder = spec.site(obj.held_by)
                if holder is None:
                    sites = sorted(s.name for s in spec.sites if s.name)
                    raise ValueError(f"object '{obj.name}': held_by '{obj.held_by}' is not a site of the robot; "
                                     f"sites: {', '.join(sites)}")
                spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name=f"{obj.name}_hold", name1=obj.name,
                                  name2=holder.parent.name, objtype=mujoco.mjtObj.mjOBJ_BODY)
        else:  # static obstacle
            spec.worldbody.add_geom(**geom, pos=obj.pose.position, quat=quat, contype=0, conaffinity=WORLD_AFFINITY)
    return spec

