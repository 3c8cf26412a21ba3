"""Generate an MJCF robot from a kinematic chain, link masses and radii.

Each moving body gets a capsule polyline from its joint to the next joint (first
along the joint axis, then across, as DH links are built), a visual housing
around the joint axis, and an explicit inertia: the link mass spread uniformly
along those capsules. MuJoCo and Pinocchio both read the result. No actuators:
rehabkit's backends apply joint torques directly, after the safety layer, and
effort limits live in :class:`~rehabkit.models.robot_model.JointLimits`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rehabkit.models.chain import KinematicChain, matrix_to_quat_wxyz

# robot geoms collide with the world (conaffinity 1) but not with each other
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 0


@dataclass(frozen=True)
class LinkSpec:
    """Physical data of the body moved by one joint.

    Attributes:
        name: Joint name (the body is ``<name>_link``).
        lower: Position limit [rad] or [m].
        upper: Position limit [rad] or [m].
        mass: Link mass [kg], spread along its capsules.
        radius: Capsule radius [m].
        damping: Viscous joint damping [N·m·s/rad].
        armature: Reflected rotor inertia of the drive [kg·m²] (both MuJoCo and Pinocchio use it).
        stiffness: Spring to zero [N·m/rad], for passive joints.
        friction: Coulomb friction of the drive [N·m, or N] (MuJoCo's ``frictionloss``; Pinocchio's ``friction``).
    """

    name: str
    lower: float
    upper: float
    mass: float
    radius: float
    damping: float = 0.0
    armature: float = 0.0
    stiffness: float = 0.0
    friction: float = 0.0


def _segment_inertia(p0: np.ndarray, p1: np.ndarray, mass: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """COM and inertia (about the COM, body axes) of a solid cylinder from p0 to p1."""
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    com = 0.5 * (p0 + p1)
    if length < 1e-9:
        return com, np.eye(3) * 0.4 * mass * radius**2
    u = axis / length
    i_axial = 0.5 * mass * radius**2
    i_perp = mass * (3 * radius**2 + length**2) / 12.0
    return com, i_perp * np.eye(3) + (i_axial - i_perp) * np.outer(u, u)


def link_inertia(points: Sequence[np.ndarray], mass: float, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass properties of a polyline of capsules carrying ``mass`` in total.

    Returns:
        COM position, principal moments, principal-axes quaternion (w, x, y, z).
    """
    segs = list(zip(points[:-1], points[1:]))
    lengths = np.array([np.linalg.norm(b - a) for a, b in segs])
    shares = lengths / lengths.sum() if lengths.sum() > 1e-9 else np.eye(len(segs))[0]
    parts = [(_segment_inertia(a, b, mass * s, radius), mass * s) for (a, b), s in zip(segs, shares)]
    com = sum(c * m for (c, _), m in parts) / mass
    inertia = np.zeros((3, 3))
    for (c, i_c), m in parts:
        r = c - com
        inertia += i_c + m * (r @ r * np.eye(3) - np.outer(r, r))
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 0] *= -1
    return com, np.maximum(moments, 1e-8), matrix_to_quat_wxyz(axes)


def _polyline(tip: np.ndarray) -> list[np.ndarray]:
    """Joint origin → along the joint axis → across to the next joint origin."""
    pts = [np.zeros(3), np.array([0.0, 0.0, tip[2]]), tip.copy()]
    keep = [pts[0]] + [p for prev, p in zip(pts, pts[1:]) if np.linalg.norm(p - prev) > 1e-9]
    return keep if len(keep) > 1 else [pts[0], pts[0]]


def build_chain_mjcf(
    name: str,
    chain: KinematicChain,
    links: Sequence[LinkSpec],
    base_radius: float = 0.05,
    ee_site: str = "ee",
    rgba: Sequence[float] = (0.35, 0.55, 0.85, 1.0),
) -> str:
    """MJCF XML of a serial robot, root body ``base`` at the origin.

    Args:
        name: Model name.
        chain: Kinematics; ``chain.dof == len(links)``.
        links: One entry per joint, base to tip.
        base_radius: Radius of the fixed base housing [m].
        ee_site: Name of the site placed at the chain tip.
        rgba: Link colour.
    """
    import mujoco  # (here, not at the top: the DH description, and rehabkit.plugin with it, import no simulator)

    if chain.dof != len(links):
        raise ValueError(f"{name}: {chain.dof} joints in the chain but {len(links)} links")
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    parent = spec.worldbody.add_body(name="base")
    parent.add_geom(
        name="base_housing", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[base_radius, 0, 0],
        contype=0, conaffinity=0, group=1, rgba=[0.3, 0.3, 0.3, 1], mass=0,
    )
    for i, link in enumerate(links):
        placement = chain.fixed[i]
        body = parent.add_body(
            name=f"{link.name}_link", pos=placement[:3, 3], quat=matrix_to_quat_wxyz(placement[:3, :3])
        )
        kind = mujoco.mjtJoint.mjJNT_HINGE if chain.joints[i] == "revolute" else mujoco.mjtJoint.mjJNT_SLIDE
        body.add_joint(
            name=link.name, type=kind, axis=[0, 0, 1], range=[link.lower, link.upper],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE, damping=link.damping,
            armature=link.armature, stiffness=link.stiffness, frictionloss=link.friction,
        )
        tip = chain.fixed[i + 1][:3, 3]
        points = _polyline(tip)
        for k, (a, b) in enumerate(zip(points[:-1], points[1:])):
            if np.linalg.norm(b - a) < 1e-9:
                body.add_geom(name=f"{link.name}_g{k}", type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=a,
                              size=[link.radius, 0, 0], contype=ROBOT_CONTYPE, conaffinity=ROBOT_CONAFFINITY,
                              rgba=rgba, mass=0)
            else:
                body.add_geom(name=f"{link.name}_g{k}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                              fromto=np.concatenate([a, b]), size=[link.radius, 0, 0],
                              contype=ROBOT_CONTYPE, conaffinity=ROBOT_CONAFFINITY, rgba=rgba, mass=0)
        body.add_geom(
            name=f"{link.name}_housing", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[1.25 * link.radius, 1.2 * link.radius, 0], contype=0, conaffinity=0, group=1,
            rgba=[0.85, 0.5, 0.2, 1], mass=0,
        )
        com, moments, iquat = link_inertia(points, link.mass, link.radius)
        body.explicitinertial = True
        body.mass, body.ipos, body.iquat, body.inertia = link.mass, com, iquat, moments
        parent = body
    tip_pose = chain.fixed[-1]
    parent.add_site(name=ee_site, pos=tip_pose[:3, 3], quat=matrix_to_quat_wxyz(tip_pose[:3, :3]), size=[0.01, 0, 0])
    spec.compile()  # fail here, with MuJoCo's message, rather than later in the backend
    return spec.to_xml()
