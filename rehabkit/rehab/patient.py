"""The patient profile (the scenario's ``patient:`` section) and the limits it sets.

A profile is pseudonymous (an id, never a name), says which side is treated,
the segment lengths a robot can adapt to, each joint's range of motion (what the
person moves on their own, ``active``, and what the joint can be moved through,
``passive``), and comfort limits on speed and interaction force. The effective
joint limits of a run are the tighter of the robot's, the profile's and the
safety envelope's, joint by joint; :func:`effective_limits` says which one set
each. The ``model`` section, when present, is a simulated-patient plugin: how
this person's arm behaves at the robot's joints in simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from rehabkit.core.interfaces import StrictModel
from rehabkit.core.plugins import suggest
from rehabkit.core.safety import SafetyConfig
from rehabkit.models.robot_model import JointLimits, RobotModel

Range = tuple[float, float]


class JointRom(StrictModel):
    """Range of motion of one joint [deg] and its comfortable speed."""

    passive_deg: Range = Field(description="range the joint can be moved through (a hard limit)")
    active_deg: Range | None = Field(None, description="range the person reaches on their own")
    max_speed_deg_s: float | None = Field(None, gt=0, description="comfortable speed of this joint")

    @model_validator(mode="after")
    def _nested(self) -> JointRom:
        lo, hi = self.passive_deg
        if lo >= hi:
            raise ValueError(f"passive_deg must be [lowest, highest], got {list(self.passive_deg)}")
        if self.active_deg is not None:
            a, b = self.active_deg
            if a >= b or a < lo or b > hi:
                raise ValueError(f"active_deg {list(self.active_deg)} must be an interval inside passive_deg "
                                 f"{list(self.passive_deg)}")
        return self


class Comfort(StrictModel):
    """Limits for the whole arm."""

    max_speed_deg_s: float | None = Field(None, gt=0, description="comfortable speed of every joint")
    max_interaction_force_n: float | None = Field(None, gt=0, description="largest force at the hand")


class PatientBase(StrictModel):
    """The plugin-independent part of a patient profile."""

    id: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", description="pseudonymous id (no names)")
    side: Literal["left", "right"] = Field(description="treated side")
    segments: dict[str, float] = Field({}, description="segment lengths [m] (e.g. upper_arm, forearm); robots "
                                                        "with a setting of the same name adapt to them")
    joints: dict[str, JointRom] = Field({}, description="range of motion per robot joint")
    comfort: Comfort = Comfort()
    outside_rom: Literal["refuse", "nearest"] = Field(
        "refuse", description="a target outside the range: refuse the scenario, or use the nearest admissible point")

    @model_validator(mode="after")
    def _positive_segments(self) -> PatientBase:
        bad = [k for k, v in self.segments.items() if not v > 0]
        if bad:
            raise ValueError(f"segment lengths must be > 0: {bad}")
        return self


@dataclass
class LimitSource:
    """Which limits a profile and an envelope tightened, joint → limit name → (source, value)."""

    by_joint: dict[str, dict[str, tuple[str, float]]]

    def as_dict(self) -> dict:
        return {j: {k: {"source": s, "value": round(v, 6)} for k, (s, v) in d.items()} for j, d in
                self.by_joint.items()}


def unknown_joint(name: str, robot: RobotModel) -> str | None:
    """The message for a joint name the robot doesn't have, with the closest ones (``None`` if it has it)."""
    if name in robot.joint_names:
        return None
    return f"no joint '{name}' on robot '{robot.name}'{suggest(name, robot.joint_names)}"


def effective_limits(robot: RobotModel, patient: PatientBase | None, safety: SafetyConfig) -> tuple[JointLimits,
                                                                                                      LimitSource]:
    """The tighter of the robot's, the patient's passive range and comfort, and the envelope's, per joint.

    A patient or envelope limit wider than the robot's leaves the robot's in force.
    """
    lim = robot.limits
    lower, upper = lim.lower.copy(), lim.upper.copy()
    velocity, effort = lim.velocity.copy(), lim.effort.copy()
    sources: dict[str, dict[str, tuple[str, float]]] = {}

    def tighten(j: int, key: str, value: float, source: str) -> None:
        arr, tighter = {"lower": (lower, value > lower[j]), "upper": (upper, value < upper[j]),
                        "velocity": (velocity, value < velocity[j]), "effort": (effort, value < effort[j])}[key]
        if tighter:
            arr[j] = value
            sources.setdefault(robot.joint_names[j], {})[key] = (source, value)

    for j, name in enumerate(robot.joint_names):
        if patient is not None:
            rom = patient.joints.get(name)
            if rom is not None:
                tighten(j, "lower", math.radians(rom.passive_deg[0]), "patient")
                tighten(j, "upper", math.radians(rom.passive_deg[1]), "patient")
                if rom.max_speed_deg_s is not None:
                    tighten(j, "velocity", math.radians(rom.max_speed_deg_s), "patient")
            if patient.comfort.max_speed_deg_s is not None:
                tighten(j, "velocity", math.radians(patient.comfort.max_speed_deg_s), "patient")
        env = safety.joints.get(name)
        if env is not None:
            if env.range_deg is not None:
                tighten(j, "lower", math.radians(env.range_deg[0]), "safety")
                tighten(j, "upper", math.radians(env.range_deg[1]), "safety")
            if env.velocity_deg_s is not None:
                tighten(j, "velocity", math.radians(env.velocity_deg_s), "safety")
            if env.torque_nm is not None:
                tighten(j, "effort", env.torque_nm, "safety")
    bad = [robot.joint_names[j] for j in range(robot.dof) if lower[j] >= upper[j]]
    if bad:
        raise ValueError(f"the patient's range and the robot's do not overlap for {bad}")
    return JointLimits(lower, upper, velocity, effort), LimitSource(sources)


def interaction_force_limit(patient: PatientBase | None, safety: SafetyConfig) -> float | None:
    """The tighter of the envelope's and the patient's comfort force limit [N]."""
    values = [v for v in (safety.interaction_force_n, patient.comfort.max_interaction_force_n if patient else None)
              if v is not None]
    return min(values) if values else None


def outside(q: np.ndarray, limits: JointLimits, tol: float = 1e-9) -> list[int]:
    """Indices of joints of ``q`` outside ``limits``."""
    return [j for j in range(len(q)) if q[j] < limits.lower[j] - tol or q[j] > limits.upper[j] + tol]
