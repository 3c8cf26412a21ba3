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


def _size3(size: list[float]) -> list[float]:
    return [*size, *([0.0] * (3 - len(size)))]


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
    spec.worldbody.add_light(name="key_light", pos=[0, -1.0, 3.0], dir=[0, 0.3, -1], diffuse=[0.8, 0.8, 0.8])
    if world.floor:
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3, 3, 0.05],
                                contype=0, conaffinity=1, rgba=[0.85, 0.85, 0.82, 1])
    for obj in world.objects:
        quat = matrix_to_quat_wxyz(rpy_to_matrix(np.radians(obj.pose.rpy_deg)))
        if obj.dynamic:
            body = spec.worldbody.add_body(name=obj.name, pos=obj.pose.position, quat=quat)
            body.add_freejoint(name=f"{obj.name}_free")
            body.add_geom(name=obj.name, type=_SHAPES[obj.shape], size=_size3(obj.size), mass=obj.mass,
                          contype=1, conaffinity=1, rgba=list(obj.rgba))
        else:
            spec.worldbody.add_geom(name=obj.name, type=_SHAPES[obj.shape], size=_size3(obj.size),
                                    pos=obj.pose.position, quat=quat, contype=0, conaffinity=1, rgba=list(obj.rgba))
    return spec

