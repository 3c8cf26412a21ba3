"""The scenario's ``safety:`` section: the envelope every command passes (the DSL; the layer enforcing it is
:mod:`rehabkit.core.safety.layer`)."""

# (no `from __future__ import annotations`: pydantic would evaluate each field's annotation from its text, as
# each model and every subclass is built, ~1 ms a module; a model's own name in a method's is quoted)
from typing import Literal

from pydantic import Field, model_validator

from rehabkit.models.strict import StrictModel

Vec3 = tuple[float, float, float]
# the rules a safety stop is made by, each with its stop category (IEC 60204-1) in ``stop_category``
STOP_RULES = ("default", "position", "velocity", "torque", "non-finite", "keep-in", "interaction-force", "e-stop",
              "plan", "plugin-error", "backend", "interrupt")


class JointEnvelope(StrictModel):
    """Limits of one joint, tighter than the robot's (a wider value changes nothing: the robot's own limits hold). A
    revolute joint's are in degrees and N·m (``range_deg``, ``velocity_deg_s``, ``torque_nm``), a prismatic joint's in
    metres and newtons (``range_m``, ``velocity_m_s``, ``force_n``); the other kind's key is refused at its line."""

    range_deg: tuple[float, float] | None = Field(None, description="[lowest, highest] position of a revolute joint "
                                                  "[deg]")
    velocity_deg_s: float | None = Field(None, gt=0, description="largest speed of a revolute joint [deg/s]")
    torque_nm: float | None = Field(None, gt=0, description="largest torque of a revolute joint [N·m]")
    range_m: tuple[float, float] | None = Field(None, description="[lowest, highest] position of a prismatic joint "
                                                "[m]")
    velocity_m_s: float | None = Field(None, gt=0, description="largest speed of a prismatic joint [m/s]")
    force_n: float | None = Field(None, gt=0, description="largest force of a prismatic joint [N]")

    @model_validator(mode="after")
    def _ordered(self) -> 'JointEnvelope':
        for key in ("range_deg", "range_m"):
            value = getattr(self, key)
            if value is not None and value[0] >= value[1]:
                raise ValueError(f"{key} must be [lowest, highest], got {list(value)}")
        return self

    def given(self) -> list[str]:
        """The keys this envelope sets."""
        return [k for k in type(self).model_fields if getattr(self, k) is not None]


class KeepInBox(StrictModel):
    """An axis-aligned box the hand (end effector) must stay in."""

    min: Vec3 = Field(description="lowest corner [m]")
    max: Vec3 = Field(description="highest corner [m]")
    frame: Literal["world", "base"] = Field("world", description="frame of the corners: world or robot base")

    @model_validator(mode="after")
    def _ordered(self) -> 'KeepInBox':
        if any(a >= b for a, b in zip(self.min, self.max)):
            raise ValueError(f"keep_in: min {list(self.min)} must be below max {list(self.max)} on every axis")
        return self


class Heartbeat(StrictModel):
    """Link timing for backends with a link (a hardware bridge); a simulator has none to watch."""

    command_timeout_ms: float = Field(50.0, gt=0, description="the robot side holds the robot without a valid "
                                                               "command this long")
    state_timeout_ms: float = Field(100.0, gt=0, description="the host stops without a valid state this long")
    hold_after_ms: float | None = Field(None, gt=0, description="the robot side holds the posture (not the last "
                                        "torque) without a newer command this long, until the next one (default: "
                                        "10 ms, or half the command timeout if that is shorter)")

    @property
    def hold_after(self) -> float:
        """The hold's delay [ms], its default filled in."""
        return self.hold_after_ms if self.hold_after_ms is not None else min(10.0, self.command_timeout_ms / 2)

    @model_validator(mode="after")
    def _ordered(self) -> 'Heartbeat':
        if self.hold_after_ms is not None and self.hold_after_ms >= self.command_timeout_ms:
            raise ValueError(f"hold_after_ms ({self.hold_after_ms:g}) must be below command_timeout_ms "
                             f"({self.command_timeout_ms:g}): the hold bridges a gap before the watchdog latches")
        return self


class ForceReaction(StrictModel):
    """What the robot does when the interaction force passes its limit (:mod:`rehabkit.core.safety.compliance`):
    ``stop`` in the rule's stop category (as every other rule), ``yield`` (compliant: gravity and friction
    compensated, damped, soft walls inside the joint ranges) or ``retreat`` (away along the force until it falls
    below ``release_n``, then hold). Its speeds and walls are a revolute joint's in degrees (``*_deg_s``,
    ``wall_deg``) and a prismatic joint's in metres (``*_m_s``, ``wall_m``): each applies to the joints of its kind
    (a key for a kind of joint the robot lacks is refused where written, with the key to write)."""

    type: Literal["stop", "yield", "retreat"] = Field(description="stop (its category), yield or retreat")
    yield_speed_deg_s: float = Field(30.0, gt=0, description="yield: the speed the force at its limit moves a "
                                     "revolute joint at, at most (sets each joint's damping) [deg/s]")
    max_speed_deg_s: float = Field(60.0, gt=0, description="a revolute joint's speed bound while yielding or "
                                   "retreating; faster is a velocity stop [deg/s]")
    wall_deg: float = Field(10.0, gt=0, description="soft walls this far inside each revolute joint's range: a joint "
                            "at the speed bound stops within it [deg]")
    release_n: float | None = Field(None, gt=0, description="retreat: hold once the force is below this (default: "
                                    "60 % of the limit)")
    retreat_speed_deg_s: float = Field(20.0, gt=0, description="retreat: the fastest revolute joint's speed [deg/s]")
    yield_speed_m_s: float = Field(0.03, gt=0, description="yield: the speed the force at its limit moves a "
                                   "prismatic joint at, at most [m/s]")
    max_speed_m_s: float = Field(0.06, gt=0, description="a prismatic joint's speed bound while yielding or "
                                 "retreating; faster is a velocity stop [m/s]")
    wall_m: float = Field(0.01, gt=0, description="soft walls this far inside each prismatic joint's range [m]")
    retreat_speed_m_s: float = Field(0.02, gt=0, description="retreat: the fastest prismatic joint's speed [m/s]")

    @model_validator(mode="after")
    def _within(self) -> 'ForceReaction':
        for bound, names in (("max_speed_deg_s", ("retreat_speed_deg_s", "yield_speed_deg_s")),
                             ("max_speed_m_s", ("retreat_speed_m_s", "yield_speed_m_s"))):
            for name in names:
                if getattr(self, name) >= getattr(self, bound):
                    raise ValueError(f"{name} ({getattr(self, name):g}) must be below {bound} "
                                     f"({getattr(self, bound):g}): moving at the speed bound would stop the robot")
        return self


class SafetyConfig(StrictModel):
    """Safety-layer settings of a scenario: the envelope every command passes."""

    position_margin_deg: float = Field(0.5, ge=0, description="tolerance beyond a revolute joint's range before "
                                       "tripping")
    position_margin_m: float = Field(0.005, ge=0, description="tolerance beyond a prismatic joint's range before "
                                     "tripping [m]")
    velocity_factor: float = Field(1.0, gt=0, description="trip above this multiple of the velocity limit")
    torque_policy: Literal["clip", "stop"] = "clip"
    stop_category: dict[Literal[STOP_RULES], Literal[0, 1, 2]] = Field(  # type: ignore[valid-type]
        {}, description="stop category per rule (IEC 60204-1): 0 torque off, 1 controlled stop then torque off, 2 "
        "controlled stop then hold; 'default' for the rules not named (default: 2, or 0 for a robot whose "
        "safe_stop is zero-torque)")
    stop_decel_deg_s2: float | None = Field(None, gt=0, description="a controlled stop's deceleration bound, each "
                                            "revolute joint [deg/s²] (default: half what each drive can give its "
                                            "joint at the trip)")
    stop_decel_m_s2: float | None = Field(None, gt=0, description="a controlled stop's deceleration bound, each "
                                          "prismatic joint [m/s²] (default: half what each drive can give its "
                                          "joint at the trip)")
    hold_kp: float = Field(60.0, gt=0, description="hold stiffness after a trip, the same SI value for every joint "
                           "[N·m/rad; N/m for a prismatic joint]")
    hold_kd: float = Field(6.0, gt=0, description="hold damping after a trip, the same SI value for every joint "
                           "[N·m·s/rad; N·s/m for a prismatic joint]")
    stop_after_s: float = Field(0.5, ge=0, description="keep simulating this long after a trip, then end the run")
    joints: dict[str, JointEnvelope] = Field({}, description="per-joint limits tighter than the robot's: a revolute "
                                             "joint's in degrees, a prismatic joint's in metres")
    keep_in: KeepInBox | None = Field(None, description="box the hand must stay in")
    interaction_force_n: float | None = Field(None, gt=0, description="largest force between person and robot "
                                                                       "at the hand")
    reactions: dict[Literal["interaction-force"], ForceReaction] = Field(
        {}, description="a force limit's reaction instead of a stop: yield (compliant) or retreat (away along the "
        "force); only the interaction-force rule limits a force, the other rules stop (stop_category)")
    ramp_in_s: float = Field(0.0, ge=0, description="soft start: blend from holding the start posture")
    ramp_out_s: float = Field(0.0, ge=0, description="soft stop: blend to holding the posture, before the end")
    heartbeat: Heartbeat | None = Field(None, description="link timing (hardware backends)")

    @model_validator(mode="after")
    def _release_below_limit(self) -> 'SafetyConfig':
        reaction = self.reactions.get("interaction-force")
        if reaction is not None and reaction.release_n is not None and self.interaction_force_n is not None \
                and reaction.release_n >= self.interaction_force_n:
            raise ValueError(f"reactions.interaction-force.release_n ({reaction.release_n:g} N) must be below "
                             f"interaction_force_n ({self.interaction_force_n:g} N): the retreat ends below the limit")
        return self

    def category_of(self, rule: str, default: int = 2) -> int:
        """The stop category ``rule`` gets: its own, else the scenario's ``default``, else ``default``."""
        return self.stop_category.get(rule, self.stop_category.get("default", default))
