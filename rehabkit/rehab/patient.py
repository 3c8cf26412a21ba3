"""What a patient's profile does to a run's limits.

The profile itself (the scenario's ``patient:`` section) is part of the DSL:
:mod:`rehabkit.rehab.profile`. Here: the tighter limits it asks for — each
joint's passive range and comfortable speed, the whole arm's comfortable speed —
and its comfortable interaction force. The run's effective limits are the tighter
of the robot's, these and the safety envelope's, joint by joint
(:func:`rehabkit.core.setup.limits.narrow` says which one set each).
"""

from __future__ import annotations

import math

from rehabkit.core.scenario.safety import SafetyConfig
from rehabkit.core.setup.limits import LimitSources, Narrowing, envelope_narrowings, narrow
from rehabkit.models.robot_model import JointLimits, RobotModel
from rehabkit.rehab.profile import Comfort, JointRom, PatientBase

__all__ = ["Comfort", "JointRom", "PatientBase", "effective_limits", "interaction_force_limit",
           "patient_narrowings"]


def patient_narrowings(robot: RobotModel, patient: PatientBase) -> list[Narrowing]:
    """The profile's limits for the robot's joints, source ``"patient"``: a revolute joint's range and comfortable
    speed from degrees, the comfortable speed of every revolute joint (``comfort.max_speed_deg_s``) and of every
    prismatic one (``comfort.max_speed_m_s``). Joints the robot lacks are skipped, and a range of motion given for a
    prismatic joint (in degrees: a person's joint turns): the extension refuses them where they are written."""
    out = []
    comfort = patient.comfort
    for name, turns in zip(robot.joint_names, robot.revolute, strict=True):
        rom = patient.joints.get(name)
        if rom is not None and turns:
            out += [Narrowing(name, "lower", math.radians(rom.passive_deg[0]), "patient"),
                    Narrowing(name, "upper", math.radians(rom.passive_deg[1]), "patient")]
            if rom.max_speed_deg_s is not None:
                out.append(Narrowing(name, "velocity", math.radians(rom.max_speed_deg_s), "patient"))
        if turns and comfort.max_speed_deg_s is not None:
            out.append(Narrowing(name, "velocity", math.radians(comfort.max_speed_deg_s), "patient"))
        if not turns and comfort.max_speed_m_s is not None:
            out.append(Narrowing(name, "velocity", comfort.max_speed_m_s, "patient"))
    return out


def effective_limits(robot: RobotModel, patient: PatientBase | None, safety: SafetyConfig
                     ) -> tuple[JointLimits, LimitSources]:
    """The tighter of the robot's, the patient's passive range and comfort, and the envelope's, per joint.

    A patient or envelope limit wider than the robot's leaves the robot's in force.
    """
    asked = patient_narrowings(robot, patient) if patient is not None else []
    return narrow(robot, [*asked, *envelope_narrowings(safety)])


def interaction_force_limit(patient: PatientBase | None, safety: SafetyConfig) -> float | None:
    """The tighter of the envelope's and the patient's comfort force limit [N]."""
    values = [v for v in (safety.interaction_force_n, patient.comfort.max_interaction_force_n if patient else None)
              if v is not None]
    return min(values) if values else None
