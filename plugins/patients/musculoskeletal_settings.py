"""The musculoskeletal patient's settings (:mod:`rehabkit_plugins.patients.musculoskeletal`): each a documented
parameter with its units; the impairments with the clinical sign they stand for."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from rehabkit.kinematics import Strap, Wearable
from rehabkit.plugin import SettingError, StrictModel, nearest, suggest

Vec3 = tuple[float, float, float]


class StrapConfig(StrictModel):
    """A cuff on a robot body."""

    segment: Literal["upper_arm", "forearm", "hand"] = Field(description="the person's segment it holds")
    body: str = Field(description="the robot's MJCF body carrying it")
    position: Vec3 = Field(description="its centre in that body's frame [m]")


class FitConfig(StrictModel):
    """Where the person sits in a robot that declares no fit of its own (the built-in exoskeletons do)."""

    shoulder: Vec3 = Field(description="the person's shoulder centre in the robot base frame [m]")
    forward: Vec3 = Field((1.0, 0.0, 0.0), description="the person's forward direction in the robot base frame")
    up: Vec3 = Field((0.0, 0.0, 1.0), description="the person's upward direction in the robot base frame")
    straps: list[StrapConfig] = Field(min_length=1, description="the cuffs holding the arm (one per segment)")

    @model_validator(mode="after")
    def _axes_and_straps(self) -> FitConfig:
        f, u = np.asarray(self.forward, float), np.asarray(self.up, float)
        for name, v in (("forward", f), ("up", u)):
            if not np.linalg.norm(v) > 1e-9:
                raise ValueError(f"{name} must be a direction, not {list(getattr(self, name))}")
        if abs(f @ u) / (np.linalg.norm(f) * np.linalg.norm(u)) > 0.2:
            raise ValueError("forward and up must be (nearly) perpendicular: the person's forward direction and "
                             "their upward one")
        segments = [s.segment for s in self.straps]
        if twice := sorted({s for s in segments if segments.count(s) > 1}):
            raise ValueError(f"straps: one per segment; {', '.join(twice)} has {segments.count(twice[0])}")
        return self


class StrapsConfig(StrictModel):
    """How the cuffs give: a linear spring-damper between the robot and the tissue under them."""

    stiffness_n_m: float = Field(3000.0, gt=0, description="cuff stiffness [N/m] (padding and soft tissue)")
    damping_ns_m: float = Field(60.0, ge=0, description="cuff damping [N·s/m]")


class Drive(StrictModel):
    """The person's intent: reach the goal, hold the arm up."""

    hand_force_n: float = Field(20.0, gt=0, description="largest voluntary hand force toward the goal [N]")
    stiffness_n_m: float = Field(200.0, ge=0, description="effort per distance to the goal [N/m]")
    damping_ns_m: float = Field(15.0, ge=0, description="effort against the hand's own speed [N·s/m]")
    delay_s: float = Field(0.2, ge=0, le=1.0, description="reaction delay: a new goal is perceived this late [s]")
    noise: float = Field(0.1, ge=0, description="signal-dependent noise: deviation as a fraction of the effort")
    noise_hz: float = Field(4.0, gt=0, description="bandwidth of that noise [Hz]")
    participation: float = Field(1.0, ge=0, le=1, description="share of the reaching effort the person makes")
    own_weight: float = Field(1.0, ge=0, le=1, description="share of their arm's weight the person holds up")


class Spasticity(StrictModel):
    """Velocity-dependent stretch reflex (a Tardieu test's catch): a muscle stretched faster than the threshold is
    excited in proportion to the excess, a reflex delay later."""

    gain: dict[str, float] = Field({}, description="excitation per L₀/s above the threshold, per muscle group "
                                                    "(elbow flexors at 0.1: ~4 N·m of reflex torque at 180°/s)")
    threshold_l0_s: float = Field(0.3, ge=0, description="lengthening speed where the reflex starts [L₀/s] "
                                                          "(0.3 is about 90°/s at the elbow)")
    reflex_delay_s: float = Field(0.04, ge=0, le=0.2, description="reflex loop delay [s]")


class TremorConfig(StrictModel):
    """Involuntary oscillation in a narrow band (e.g. 4–6 Hz after a stroke or in Parkinson's disease)."""

    amplitude_nm: dict[str, float] = Field({}, description="RMS tremor torque per joint [N·m]")
    frequency_hz: float = Field(5.0, gt=0, le=20, description="centre frequency [Hz]")
    bandwidth_hz: float = Field(0.5, gt=0, description="width of the band [Hz]")


class Synergy(StrictModel):
    """Abnormal flexor synergy: effort to abduct (elevate) the shoulder flexes the elbow with it."""

    elbow_per_shoulder: float = Field(0.0, ge=0, description="elbow-flexion torque per N·m of shoulder "
                                                              "elevation effort [N·m/N·m]")


class FatigueConfig(StrictModel):
    """Per-muscle capacity: falls with activation, recovers at rest."""

    rate_per_s: float = Field(0.0, ge=0, description="capacity lost per second at full activation [1/s]")
    recovery_per_s: float = Field(0.01, ge=0, description="share of the lost capacity regained per second at rest")


class MusculoskeletalConfig(StrictModel):
    """A muscle-driven arm (MyoSuite) strapped into the robot; impairments are illustrative parameters."""

    model: Literal["myoarm", "myoelbow"] = Field("myoarm", description="MyoArm (shoulder to hand, 63 muscles) or "
                                                                       "MyoElbow (the elbow, 6 muscles)")
    straps: StrapsConfig = StrapsConfig()
    fit: FitConfig | None = Field(None, description="where the person sits (default: the robot's own fit)")
    drive: Drive = Drive()
    weakness: dict[str, Annotated[float, Field(gt=0, le=1)]] = Field(
        {}, description="force scale per muscle group, in (0, 1] (1: full strength)")
    spasticity: Spasticity = Spasticity()
    tremor: TremorConfig = TremorConfig()
    synergy: Synergy = Synergy()
    fatigue: FatigueConfig = FatigueConfig()
    contracture_deg: dict[str, tuple[float, float]] = Field(
        {}, description="reduced passive range per joint [deg] (the model's joint convention)")
    scale_to_profile: bool = Field(True, description="stretch the arm's upper arm and forearm to the profile's "
                                                     "segments (upper_arm: shoulder centre to elbow; forearm: elbow "
                                                     "to the middle of the grip)")

def per_group(values: dict[str, float], arm_groups: dict[str, tuple[str, ...]], n: int, what: str,
              default: float) -> np.ndarray:
    """A value per muscle from ``values`` per muscle group (``what``: the setting, for a name not in the arm)."""
    out = np.full(n, default)
    names = {g: i for i, g in enumerate(arm_groups)}
    start = np.cumsum([0, *(len(m) for m in arm_groups.values())])
    for group, value in values.items():
        if group not in names:
            raise SettingError((*what.split("."), group), f"no muscle group '{group}' in this arm",
                               fix=nearest(group, arm_groups))
        out[start[names[group]] : start[names[group] + 1]] = value
    return out


def wearable_for(config: MusculoskeletalConfig, cat, robot, profile) -> Wearable:
    """How the arm (``cat``: its catalogue entry) is strapped into ``robot`` (its model): the scenario's fit, else
    the robot's own; the settings checked against both (each name used is there) and the ``profile``'s side."""
    if profile is not None and profile.side != cat.side:
        raise SettingError("model", f"{config.model} is a {cat.side} arm; the profile treats the {profile.side} side "
                           "(mirrored arms are not available)")
    fit = config.fit
    wearable = Wearable(fit.shoulder, fit.forward, fit.up, tuple(Strap(s.segment, s.body, s.position)
                        for s in fit.straps)) if fit else robot.wearable
    if wearable is None:
        raise SettingError("fit", f"robot '{robot.name}' declares no fit for a person: give fit (shoulder and straps)")
    wearable.person_axes()  # (a robot's own declaration checked as the scenario's is)
    bodies = {e.get("name") for e in ET.fromstring(robot.mjcf).iter("body")}
    for strap in wearable.straps:
        if strap.body not in bodies:
            raise SettingError(("fit", "straps") if fit else "fit",
                               f"strap on the {strap.segment}: robot '{robot.name}' has no body "
                               f"'{strap.body}'{suggest(strap.body, bodies)}; "
                               f"its bodies: {', '.join(sorted(b for b in bodies if b))}")
    if config.model == "myoelbow" and any(s.segment == "upper_arm" for s in wearable.straps):
        raise SettingError("model", "MyoElbow's upper arm is fixed to its trunk; strap its forearm or hand only")
    for field, names in (("tremor.amplitude_nm", config.tremor.amplitude_nm),
                         ("contracture_deg", config.contracture_deg)):
        for name in names:
            if name not in cat.joints:
                raise SettingError((*field.split("."), name), f"no joint '{name}' in {config.model}",
                                   fix=nearest(name, cat.joints))
    if config.synergy.elbow_per_shoulder > 0 and "shoulder_elevation" not in cat.joints:
        raise SettingError("synergy", f"{config.model} has no shoulder")
    return wearable
