"""Fitting a run to its patient before anything moves: segment lengths, narrowed limits, admitted targets.

Targets with joint values are checked directly; Cartesian ones through the robot's
IK (some posture within the robot's ranges must also be within the narrowed
ones). A target outside is refused with its place in the YAML, the joint and
both ranges named, or — where the profile says ``outside_rom: nearest`` —
replaced by the nearest admissible posture (joint values clipped into the range;
a Cartesian target moves to where that posture puts the hand).
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from rehabkit.core.kinds.interfaces import Robot, StrictModel, Target
from rehabkit.core.safety.limit_breach import LimitBreach, outside
from rehabkit.core.scenario.errors import Diagnostic, ScenarioError
from rehabkit.core.scenario.models import TaskSpec
from rehabkit.core.setup.limits import LimitSources, Narrowing, unknown_joint
from rehabkit.models.robot_model import JointLimits, RobotModel
from rehabkit.rehab.patient import patient_narrowings
from rehabkit.rehab.profile import PatientBase


def adapt_segments(robot_cfg: StrictModel, profile: PatientBase | None, source) -> tuple[StrictModel, dict[str, str]]:
    """The robot section with the patient's segment lengths where the robot has a setting of that name
    (unless the scenario sets it), and what became of each length."""
    notes: dict[str, str] = {}
    if profile is None:
        return robot_cfg, notes
    fields, update = type(robot_cfg).model_fields, {}
    for name, length in profile.segments.items():
        if name not in fields:
            notes[name] = f"robot '{robot_cfg.type}' has no setting '{name}': not adapted"
        elif ("robot", name) in source.value_marks:
            notes[name] = f"robot.{name} = {getattr(robot_cfg, name)} set in the scenario wins"
        else:
            update[name] = length
            notes[name] = f"robot.{name} = {length} (from the profile)"
    return robot_cfg.model_copy(update=update), notes


def sliding_rom(name: str, model: RobotModel) -> tuple[str, str] | None:
    """The message for a range of motion given for a prismatic joint (a person's is in degrees) and its fix, else
    None."""
    j = model.joint_names.index(name)
    if model.revolute[j]:
        return None
    lo, hi = model.limits.lower[j], model.limits.upper[j]
    return (f"{name} is a prismatic joint: a range of motion (passive_deg, active_deg, max_speed_deg_s) is a revolute "
            "joint's, in degrees", f"limit a prismatic joint in the safety envelope instead, in metres (safety.joints."
            f"{name}: {{range_m: [{lo:.4g}, {hi:.4g}], velocity_m_s: ...}}: the robot's own range)")


def profile_narrowings(model: RobotModel, profile: PatientBase, source) -> list[Narrowing]:
    """The profile's tighter limits; joint names the robot lacks are refused where they are written
    (:class:`ScenarioError`)."""
    problems = []
    for name in profile.joints:
        said = unknown_joint(name, model) or sliding_rom(name, model)
        if said is not None:
            path = ("patient", "joints", name)
            problems.append(Diagnostic(source.key_marks.get(path, source.value_marks[()]), ".".join(path), *said))
    if problems:
        raise ScenarioError(problems)
    return patient_narrowings(model, profile)


@contextmanager
def _robot_limits(robot: Robot, limits: JointLimits):
    """The robot's own limits for a moment (its IK filters solutions by the model's limits)."""
    narrowed, robot.model.limits = robot.model.limits, limits
    try:
        yield
    finally:
        robot.model.limits = narrowed


def _into_range(q: np.ndarray, limits: JointLimits) -> np.ndarray:
    """Angles shifted by whole turns into the range where that helps."""
    q = np.array(q, float)
    for j in range(len(q)):
        for shift in (0.0, 2 * math.pi, -2 * math.pi):
            if limits.lower[j] <= q[j] + shift <= limits.upper[j]:
                q[j] += shift
                break
    return q


def _violation(q: np.ndarray, limits: JointLimits) -> float:
    return float(np.sum(np.maximum(0, limits.lower - q) + np.maximum(0, q - limits.upper)))


def _posture(target: Target, robot: Robot, robot_limits: JointLimits) -> np.ndarray | None:
    """The target's joint values, or the robot-admissible IK posture nearest the narrowed ranges."""
    if target.q is not None:
        return np.asarray(target.q, float)
    if target.pose is None:
        return None
    try:
        with _robot_limits(robot, robot_limits):
            solutions = robot.ik(target.pose)
    except NotImplementedError:
        return None  # no IK: the planner's limit check sees its via points
    inside = [s for s in (_into_range(s, robot_limits) for s in solutions)
              if np.all(s >= robot_limits.lower - 1e-9) and np.all(s <= robot_limits.upper + 1e-9)]
    if not inside:
        return None  # out of the robot's reach: the planner says so
    return min(inside, key=lambda s: _violation(s, robot.model.limits))


def admit_targets(targets: dict[str, Target], task: TaskSpec, robot: Robot, robot_limits: JointLimits,
                  sources: LimitSources, profile: PatientBase | None, source) -> list[dict]:
    """Check (and where asked, replace) every fixed target; returns the replacements made.

    Raises:
        ScenarioError: a target outside the narrowed ranges, located at the target in the YAML.
    """
    limits, names = robot.model.limits, robot.model.joint_names
    narrowed = [j for j, n in enumerate(names) if sources.range_narrowed(n)]
    if not narrowed:
        return []
    nearest = profile is not None and profile.outside_rom == "nearest"
    problems, replaced = [], []
    for i, spec in enumerate(task.targets):
        tgt = targets[spec.name]
        if spec.sensor or spec.random is not None or tgt.same_as:
            continue  # sensed and random targets come from the narrowed workspace; aliases follow their original
        q = _posture(tgt, robot, robot_limits)
        if q is None:
            continue
        bad = [j for j in outside(q, limits) if j in narrowed]
        if not bad:
            continue
        if nearest:
            q_new = np.clip(q, limits.lower, limits.upper)
            pose = robot.fk(q_new)
            targets[spec.name] = Target(spec.name, q=q_new if tgt.q is not None else None, pose=pose,
                                        position_only=tgt.position_only)
            replaced.append({"target": spec.name, "joints": [names[j] for j in bad],
                             "from_deg": np.round(np.degrees(q), 3).tolist(),
                             "to_deg": np.round(np.degrees(q_new), 3).tolist(),
                             "moved_m": float(np.linalg.norm(pose[:3, 3] - tgt.pose[:3, 3]))})
            continue
        path = ("task", "targets", i)
        mark = source.value_marks.get(path, source.value_marks[()])
        for j in bad:
            who, _ = sources.by_joint[names[j]].get("upper" if q[j] > limits.upper[j] else "lower")
            whose = f"patient {profile.id}'s passive range" if who == "patient" else "the safety envelope's range"
            how = "its joint values put" if tgt.q is not None else "the posture the IK finds for it puts"
            high = q[j] > limits.upper[j]
            turns = bool(robot.model.revolute[j])  # (a prismatic joint's range in metres)
            breach = LimitBreach("position", names[j], float(q[j]), float(limits.upper[j] if high else limits.lower[j]),
                                 revolute=turns)
            # (nearest is a patient profile's choice: without one, the envelope's range is the one to change)
            fix = ("set patient.outside_rom: nearest to use the nearest admissible point" if profile is not None else
                   f"widen safety.joints.{names[j]}.range_{'deg' if turns else 'm'}")
            span = (f"[{math.degrees(limits.lower[j]):.1f}, {math.degrees(limits.upper[j]):.1f}]°" if turns else
                    f"[{limits.lower[j]:.4g}, {limits.upper[j]:.4g}] m")
            problems.append(Diagnostic(mark, ".".join(map(str, path)),
                                       f"target '{spec.name}': {how} {breach.describe()}: {whose} is {span}",
                                       f"move the target into the range, or {fix}"))
    if problems:
        raise ScenarioError(problems)
    for spec in task.targets:  # aliases of a replaced target go where it went
        tgt = targets[spec.name]
        if tgt.same_as and any(r["target"] == tgt.same_as for r in replaced):
            orig = targets[tgt.same_as]
            targets[spec.name] = Target(spec.name, q=None if orig.q is None else orig.q.copy(),
                                        pose=orig.pose.copy(), position_only=orig.position_only, same_as=tgt.same_as)
    return replaced
