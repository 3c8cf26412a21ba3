"""Robots described by a DH table in YAML: the models and the builder.

A description has two parts. ``table`` is the kinematics, rows exactly as a
paper prints them (standard or modified convention). ``joints`` is the
physical robot, base to tip: names, limits, the mass and radius of the link
each joint moves. With ``reverse: true`` the table describes the chain from
tip to base (the reverse coordinate method); the physical joint i is then
table row n+1-i with its variable negated.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails

from rehabkit.models.chain import DHRow, KinematicChain, pose
from rehabkit.models.mjcf_builder import LinkSpec, build_chain_mjcf
from rehabkit.models.robot_model import JointLimits, RobotModel, SafeStop
from rehabkit.models.strict import StrictModel

Vec3 = tuple[float, float, float]


class PoseSpec(StrictModel):
    """Position [m] and roll-pitch-yaw [deg]."""

    position: Vec3 = (0.0, 0.0, 0.0)
    rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        return pose(self.position, np.radians(self.rpy_deg))


class DHRowSpec(StrictModel):
    """One table row. For ``modified``, ``a`` and ``alpha_deg`` are a_{i-1}, alpha_{i-1}."""

    a: float = 0.0
    alpha_deg: float = 0.0
    d: float = 0.0
    theta_deg: float = Field(0.0, description="constant offset added to the joint angle")
    joint: Literal["revolute", "prismatic"] = "revolute"

    def row(self) -> DHRow:
        return DHRow(self.a, np.radians(self.alpha_deg), self.d, np.radians(self.theta_deg), self.joint)


class JointSpec(StrictModel):
    """A physical joint and the link it moves. Revolute: degrees; prismatic: metres."""

    name: str
    range_deg: tuple[float, float] | None = None
    range_m: tuple[float, float] | None = None
    velocity_deg_s: float | None = Field(None, gt=0)
    velocity_m_s: float | None = Field(None, gt=0)
    effort: float = Field(gt=0, description="torque [N·m] or force [N] limit")
    mass: float = Field(gt=0, description="[kg]")
    radius: float = Field(0.03, gt=0, description="capsule radius [m]")
    damping: float = Field(0.0, ge=0, description="viscous damping [N·m·s/rad, or N·s/m for a prismatic joint]")
    friction: float = Field(0.0, ge=0, description="Coulomb friction of the drive [N·m, or N for a prismatic joint]: "
                                                   "simulated as dry friction, compensated by the inverse-dynamics "
                                                   "feedforward")
    armature: float = Field(0.0, ge=0, description="reflected rotor inertia of the drive [kg·m²]")
    stiffness: float = Field(0.0, ge=0, description="spring toward zero [N·m/rad] (passive joints)")
    brake: float = Field(0.0, ge=0, description="holding brake [N·m or N], engaged when the torque goes off (safety "
                                                "stop categories 0 and 1); 0: none")

    @model_validator(mode="after")
    def _one_unit(self) -> JointSpec:
        if (self.range_deg is None) == (self.range_m is None):
            raise ValueError(f"joint '{self.name}': give range_deg (revolute) or range_m (prismatic)")
        if (self.velocity_deg_s is None) == (self.velocity_m_s is None):
            raise ValueError(f"joint '{self.name}': give velocity_deg_s (revolute) or velocity_m_s (prismatic)")
        if (self.range_deg is None) != (self.velocity_deg_s is None):  # (a crash in the robot's build before)
            given, fix = ("range_m", "velocity_m_s") if self.range_m is not None else ("range_deg", "velocity_deg_s")
            raise ValueError(f"joint '{self.name}': {given} with a speed of the other kind: write {fix}, in the "
                             "same kind of unit as its range (degrees for a revolute joint, metres for a prismatic)")
        return self

    @property
    def revolute(self) -> bool:
        return self.range_deg is not None

    def limits(self) -> tuple[float, float, float]:
        """lower, upper, velocity in SI units."""
        if self.revolute:
            lo, hi = np.radians(self.range_deg)
            return float(lo), float(hi), float(np.radians(self.velocity_deg_s))
        return self.range_m[0], self.range_m[1], float(self.velocity_m_s)


class DHRobotSpec(StrictModel):
    """A complete DH robot description (the ``dh`` robot plugin's config)."""

    name: str = "dh-robot"
    convention: Literal["standard", "modified"]
    reverse: bool = Field(False, description="the table runs from the tip to the base")
    table: list[DHRowSpec] = Field(min_length=1)
    joints: list[JointSpec] = Field(min_length=1, description="physical joints, base to tip")
    tool: PoseSpec = Field(PoseSpec(), description="end-effector frame relative to the chain tip")
    base: PoseSpec = Field(PoseSpec(), description="robot base in the world")
    base_radius: float = Field(0.05, gt=0)
    safe_stop: SafeStop = "hold"

    @model_validator(mode="after")
    def _same_length(self) -> DHRobotSpec:
        if len(self.table) != len(self.joints):
            raise ValueError(f"the table has {len(self.table)} rows but {len(self.joints)} joints are described")
        table_kinds = [r.joint for r in (reversed(self.table) if self.reverse else self.table)]
        wrong = []  # each key of the other kind, at its own place in the file
        for i, (j, kind) in enumerate(zip(self.joints, table_kinds)):
            if j.revolute != (kind == "revolute"):
                keys = ("range_deg", "velocity_deg_s") if kind == "prismatic" else ("range_m", "velocity_m_s")
                for key in keys:
                    fix = key.replace("_deg_s", "_m_s").replace("_deg", "_m") if kind == "prismatic" else \
                        key.replace("_m_s", "_deg_s").replace("range_m", "range_deg")
                    unit = "metres" if kind == "prismatic" else "degrees"
                    wrong.append(InitErrorDetails(type="value_error", loc=("joints", i, key), input=getattr(j, key),
                                                  ctx={"error": ValueError(
                                                      f"joint '{j.name}' is {kind} in the table: write {fix} "
                                                      f"instead, in {unit}")}))
        if wrong:
            raise ValidationError.from_exception_data(type(self).__name__, wrong)
        return self

    def table_chain(self) -> KinematicChain:
        """The chain exactly as the table describes it (tip to base when ``reverse``)."""
        return KinematicChain.from_dh([r.row() for r in self.table], self.convention)

    def chain(self) -> KinematicChain:
        """The physical chain, base to tip, tool frame included."""
        chain = self.table_chain()
        if self.reverse:
            chain = chain.reversed()
        tool = self.tool.matrix()
        return KinematicChain((*chain.fixed[:-1], chain.fixed[-1] @ tool), chain.joints)


def links_and_limits(joints: list[JointSpec]) -> tuple[list[LinkSpec], JointLimits]:
    """The MJCF builder's link data and the joint limits, in SI units, from joint specs."""
    links, rows = [], []
    for j in joints:
        lo, hi, v = j.limits()
        links.append(LinkSpec(j.name, lo, hi, j.mass, j.radius, j.damping, j.armature, j.stiffness, j.friction))
        rows.append((lo, hi, v, j.effort))
    return links, JointLimits(*(np.array(col) for col in zip(*rows)))


def build_dh_robot(spec: DHRobotSpec, ee_site: str = "ee") -> RobotModel:
    """MJCF + limits for a DH robot; Pinocchio reads the same MJCF."""
    links, limits = links_and_limits(spec.joints)
    xml = build_chain_mjcf(spec.name, spec.chain(), links, base_radius=spec.base_radius, ee_site=ee_site)
    return RobotModel(
        name=spec.name, mjcf=xml, joint_names=[j.name for j in spec.joints], limits=limits,
        ee_site=ee_site, base_pose=spec.base.matrix(), safe_stop=spec.safe_stop,
        brakes=np.array([j.brake for j in spec.joints]) if any(j.brake for j in spec.joints) else None,
    )

