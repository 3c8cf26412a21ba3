"""The ``learning:`` section: the scenario as a reinforcement-learning environment (``rehabkit.gym``).

What the policy does (``action``), what it sees (``observation``), what it is paid (``reward``, weighted terms) and
how often it acts (``policy_hz``, over the control loop). The DSL only, contributed to every scenario through the
``rehabkit_scenario_sections`` hook (an extension); the environment itself is :mod:`rehabkit.gym`.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Section
from rehabkit.models.strict import StrictModel

OBSERVATION_TERMS = ("joint_state", "reference", "tracking_error", "goal", "phase", "interaction_force",
                     "person_torque", "person_state", "pixels")
REWARD_TERMS = ("tracking", "interaction_force", "assistance", "jerk", "reached")


Fraction = Annotated[float, Field(gt=0, le=1)]  # (bounds on each branch of a union: JSON Schema has none on a union)


class ActionSpec(StrictModel):
    """What the policy's action in [−1, 1]ⁿ does."""

    kind: Literal["residual", "torque", "parameters"] = Field(
        "residual", description="residual: a torque added to the scenario's controller's; torque: the whole torque "
                                "(on top of the robot's own gravity compensation); parameters: the controller's own "
                                "settings, each over its range")
    parameters: dict[str, tuple[float, float]] = Field(
        {}, description="parameters: setting → [value at −1, value at +1] (e.g. assist-as-needed's k_max)")
    scale: Fraction | list[Fraction] = Field(
        0.2, description="action 1.0 is this fraction of each joint's effort limit (one value or one per joint)")

    @model_validator(mode="after")
    def _positive(self) -> ActionSpec:
        values = self.scale if isinstance(self.scale, list) else [self.scale]
        if not values or any(not 0 < v <= 1 for v in values):
            raise ValueError("scale: each fraction of the effort limit must be in (0, 1]")
        if (self.kind == "parameters") != bool(self.parameters):
            raise ValueError("parameters: give the settings the action tunes, and only with kind: parameters")
        return self


class ObservationSpec(StrictModel):
    """What the policy sees each time it acts."""

    terms: list[Literal[OBSERVATION_TERMS]] = Field(  # type: ignore[valid-type]
        ["joint_state", "tracking_error", "phase"], min_length=1,
        description="joint_state (q, q̇), reference (q_ref, q̇_ref), tracking_error (q_ref − q), goal (of the movement "
                    "under way), phase (time / duration), interaction_force (the person's, N), person_torque (at the "
                    "joints, N·m), person_state (a simulated person's inner state, e.g. fatigue), "
                    "pixels (a camera image; only with layout: dict)")
    layout: Literal["box", "dict"] = Field("box", description="box: one flat vector; dict: a term each")
    camera: str | None = Field(None, description="the world camera the pixels term renders")
    width: int = Field(64, ge=8, le=512, description="pixels: image width")
    height: int = Field(64, ge=8, le=512, description="pixels: image height")

    @model_validator(mode="after")
    def _pixels(self) -> ObservationSpec:
        if "pixels" in self.terms and (self.layout != "dict" or self.camera is None):
            raise ValueError("terms: pixels needs layout: dict and a camera")
        if len(set(self.terms)) != len(self.terms):
            raise ValueError("terms: each term once")
        return self


class LearningSpec(StrictModel):
    """The scenario as an environment: the policy acts at ``policy_hz`` over the control loop."""

    policy_hz: float = Field(50.0, gt=0, description="how often the policy acts [Hz] (a divisor of the control rate)")
    stop_penalty: float = Field(
        10.0, ge=0, description="taken from the reward of the step a safety stop ends the episode on (else a policy "
                                "paid by the step's costs learns to stop the robot early)")
    action: ActionSpec = ActionSpec()
    observation: ObservationSpec = ObservationSpec()
    reward: dict[Literal[REWARD_TERMS], float] = Field(  # type: ignore[valid-type]
        {"tracking": 1.0}, min_length=1,
        description="weight per term, each per second of the policy step: tracking (−mean squared tracking error, "
                    "rad²), interaction_force (−mean force, N), assistance (−mean squared robot torque beyond its "
                    "gravity compensation, (N·m)²), jerk (−mean squared joint jerk, (rad/s³)², ×1e-6), reached "
                    "(+1 a step once the goal of the movement under way is within the outcome tolerance)")


@hookimpl
def rehabkit_scenario_sections(registry) -> dict[str, Section]:
    return {"learning": Section(LearningSpec, None, "the scenario as a learning environment (rehabkit.gym)")}
