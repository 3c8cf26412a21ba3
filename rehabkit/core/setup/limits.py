"""Joint limits of a run: how they are narrowed, and the one description of a breach.

A run's limits start as the robot's; the safety envelope (``safety.joints``) and
any extension (the rehab layer: the patient's range and comfort speed) may only
tighten them, joint by joint. :class:`LimitSources` says who set each tightened
value. Every place that finds a joint beyond a limit — the safety layer, the plan
check, target admission, the bridge — describes it as a :class:`LimitBreach`, so
the message reads the same everywhere and tests can assert on its fields.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from rehabkit.core.kinds.names import nearest
from rehabkit.models.robot_model import JointLimits, RobotModel

Key = Literal["lower", "upper", "velocity", "effort"]


@dataclass(frozen=True)
class Narrowing:
    """One proposed tighter limit: joint name, which limit, its value (SI: rad, rad/s, N·m) and who asks."""

    joint: str
    key: Key
    value: float
    source: str


@dataclass
class LimitSources:
    """Which limits were tightened, joint → limit name → (source, value)."""

    by_joint: dict[str, dict[str, tuple[str, float]]] = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {j: {k: {"source": s, "value": round(v, 6)} for k, (s, v) in d.items()} for j, d in
                self.by_joint.items()}

    def range_narrowed(self, joint: str) -> bool:
        return bool({"lower", "upper"} & set(self.by_joint.get(joint, {})))


def unknown_joint(name: str, robot: RobotModel) -> tuple[str, str] | None:
    """The message for a joint name the robot doesn't have and its fix, the closest ones (``None`` if it has it)."""
    if name in robot.joint_names:
        return None
    return f"no joint '{name}' on robot '{robot.name}'", nearest(name, robot.joint_names)


def narrow(robot: RobotModel, narrowings: Iterable[Narrowing]) -> tuple[JointLimits, LimitSources]:
    """The robot's limits tightened by ``narrowings`` (in order; a wider value leaves the limit as it is).

    Raises:
        ValueError: a joint's range becomes empty.
    """
    lim = robot.limits
    arrays = {"lower": lim.lower.copy(), "upper": lim.upper.copy(), "velocity": lim.velocity.copy(),
              "effort": lim.effort.copy()}
    sources = LimitSources()
    index = {n: j for j, n in enumerate(robot.joint_names)}
    for nw in narrowings:
        j, arr = index[nw.joint], arrays[nw.key]
        tighter = nw.value > arr[j] if nw.key == "lower" else nw.value < arr[j]
        if tighter:
            arr[j] = nw.value
            sources.by_joint.setdefault(nw.joint, {})[nw.key] = (nw.source, nw.value)
    bad = [robot.joint_names[j] for j in range(robot.dof) if arrays["lower"][j] >= arrays["upper"][j]]
    if bad:
        whose = sorted({s for n in bad for s, _ in sources.by_joint.get(n, {}).values()})
        raise ValueError(f"the ranges of {' and '.join(whose) or 'the limits'} and the robot's do not overlap "
                         f"for {bad}")
    return JointLimits(**arrays), sources


# a joint envelope's keys by the kind of joint they are for, each with its counterpart on the other kind
REVOLUTE_KEYS = {"range_deg": "range_m", "velocity_deg_s": "velocity_m_s", "torque_nm": "force_n"}
PRISMATIC_KEYS = {v: k for k, v in REVOLUTE_KEYS.items()}
KEY_UNITS = {"range_deg": "deg", "velocity_deg_s": "deg/s", "torque_nm": "N·m", "range_m": "m", "velocity_m_s": "m/s",
             "force_n": "N"}


@dataclass(frozen=True)
class WrongUnitKey:
    """A per-joint setting written in the other kind of joint's unit (``range_deg`` on a prismatic joint).

    Attributes:
        joint: The joint's name.
        key: The key as written.
        takes: The key its joint takes (``range_m``).
        revolute: Whether the joint is revolute.
        robot_value: The robot's own limit that key sets, in the joint's unit (``[0, 0.04] m``).
    """

    joint: str
    key: str
    takes: str
    revolute: bool
    robot_value: str

    @property
    def problem(self) -> str:
        """``finger is a prismatic joint: range_deg [deg] is for a revolute joint``."""
        kind, other = ("revolute", "prismatic") if self.revolute else ("prismatic", "revolute")
        return f"{self.joint} is a {kind} joint: {self.key} [{KEY_UNITS[self.key]}] is for a {other} joint"

    @property
    def fix(self) -> str:
        """``write range_m instead, in m (the robot's own: [0, 0.04] m)``."""
        return f"write {self.takes} instead, in {KEY_UNITS[self.takes]} (the robot's own: {self.robot_value})"

    def describe(self) -> str:
        """The problem, then its fix: ``finger is a prismatic joint: range_deg [deg] is for a revolute joint; write
        range_m instead, in m (the robot's own: [0, 0.04] m)``."""
        return f"{self.problem}; {self.fix}"


def wrong_unit_keys(given: dict[str, list[str]], model: RobotModel) -> list[WrongUnitKey]:
    """The per-joint keys (joint name → keys written) that are for the other kind of joint than the robot's: a
    degrees key on a prismatic joint, a metres one on a revolute joint. Joints the robot lacks are skipped (said
    elsewhere)."""
    out = []
    for name, keys in given.items():
        if name not in model.joint_names:
            continue
        j = model.joint_names.index(name)
        revolute = bool(model.revolute[j])
        wrong = PRISMATIC_KEYS if revolute else REVOLUTE_KEYS
        lim, scale = model.limits, math.degrees(1.0) if revolute else 1.0
        for key in keys:
            if key not in wrong:
                continue
            fix = wrong[key]
            own = {"range": f"[{lim.lower[j] * scale:.4g}, {lim.upper[j] * scale:.4g}]",
                   "velocity": f"{lim.velocity[j] * scale:.4g}"}.get(fix.split("_")[0], f"{lim.effort[j]:.4g}")
            out.append(WrongUnitKey(name, key, fix, revolute, f"{own} {KEY_UNITS[fix]}"))
    return out


# the envelope's settings for every joint of one kind (safety.*, safety.reactions.*), each with its counterpart
KIND_SETTINGS = {"position_margin_deg": "position_margin_m", "stop_decel_deg_s2": "stop_decel_m_s2",
                 "yield_speed_deg_s": "yield_speed_m_s", "max_speed_deg_s": "max_speed_m_s", "wall_deg": "wall_m",
                 "retreat_speed_deg_s": "retreat_speed_m_s"}
SETTING_UNITS = {"position_margin_deg": "deg", "stop_decel_deg_s2": "deg/s²", "yield_speed_deg_s": "deg/s",
                 "max_speed_deg_s": "deg/s", "wall_deg": "deg", "retreat_speed_deg_s": "deg/s",
                 "position_margin_m": "m", "stop_decel_m_s2": "m/s²", "yield_speed_m_s": "m/s", "max_speed_m_s": "m/s",
                 "wall_m": "m", "retreat_speed_m_s": "m/s"}


def wrong_kind_settings(given: Iterable[str], model: RobotModel) -> dict[str, tuple[str, str]]:
    """The settings among ``given`` (keys written) that hold for a kind of joint the robot has none of — a degrees
    one on a robot whose joints all slide, a metres one on a robot whose joints all turn — each with its message and
    fix: ``robot 'hit' has no prismatic joint: wall_m [m] is for prismatic joints``, ``write wall_deg instead, in
    deg, for its revolute joints``."""
    metres = {v: k for k, v in KIND_SETTINGS.items()}
    has = {True: bool(np.any(model.revolute)), False: not bool(np.all(model.revolute))}
    out = {}
    for key in given:
        if key not in KIND_SETTINGS and key not in metres:
            continue
        turns = key in KIND_SETTINGS
        if has[turns]:
            continue
        fix = KIND_SETTINGS[key] if turns else metres[key]
        kind, other = ("revolute", "prismatic") if turns else ("prismatic", "revolute")
        out[key] = (f"robot '{model.name}' has no {kind} joint: {key} [{SETTING_UNITS[key]}] is for {kind} joints",
                    f"write {fix} instead, in {SETTING_UNITS[fix]}, for its {other} joints")
    return out


def envelope_narrowings(safety) -> list[Narrowing]:
    """The safety envelope's per-joint limits (``safety.joints``) as narrowings, source ``"safety"``: a revolute
    joint's from degrees and N·m, a prismatic joint's from metres and N (which key fits which joint is checked
    where the limits are narrowed: :func:`wrong_unit_keys`)."""
    out = []
    for name, env in safety.joints.items():
        if env.range_deg is not None:
            out += [Narrowing(name, "lower", math.radians(env.range_deg[0]), "safety"),
                    Narrowing(name, "upper", math.radians(env.range_deg[1]), "safety")]
        if env.range_m is not None:
            out += [Narrowing(name, "lower", float(env.range_m[0]), "safety"),
                    Narrowing(name, "upper", float(env.range_m[1]), "safety")]
        if env.velocity_deg_s is not None:
            out.append(Narrowing(name, "velocity", math.radians(env.velocity_deg_s), "safety"))
        if env.velocity_m_s is not None:
            out.append(Narrowing(name, "velocity", float(env.velocity_m_s), "safety"))
        if env.torque_nm is not None:
            out.append(Narrowing(name, "effort", env.torque_nm, "safety"))
        if env.force_n is not None:
            out.append(Narrowing(name, "effort", env.force_n, "safety"))
    return out
