"""The patient profile: the scenario's ``patient:`` section, the rehab layer's (the DSL only).

A profile is pseudonymous (an id, never a name), says which side is treated,
the segment lengths a robot can adapt to, each joint's range of motion (what the
person moves on their own, ``active``, and what the joint can be moved through,
``passive``), and comfort limits on speed and interaction force. What a run does
with it (narrowed limits, admitted targets, adapted segments) is the rehab
extension's (:mod:`rehabkit.rehab.extension`); the ``model`` section, when
present, is a simulated-patient plugin (a core plugin kind: the section declares it as its plugin slot).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from rehabkit.core.kinds.interfaces import StrictModel
from rehabkit.core.kinds.patient import JointRom  # (a core kind's: a simulated person has its own)

Range = tuple[float, float]


class Comfort(StrictModel):
    """Limits for the whole arm."""

    max_speed_deg_s: float | None = Field(None, gt=0, description="comfortable speed of every revolute joint "
                                          "[deg/s]")
    max_speed_m_s: float | None = Field(None, gt=0, description="comfortable speed of every prismatic joint [m/s]")
    max_interaction_force_n: float | None = Field(None, gt=0, description="largest force at the hand")


class Impairment(StrictModel):
    """What the person is treated for and how it was scored (a study's dataset lists it per participant)."""

    condition: str = Field(description="e.g. 'post-stroke hemiparesis'")
    scale: str | None = Field(None, description="the clinical scale scored, e.g. 'Fugl-Meyer upper extremity (0-66)'")
    score: float | None = Field(None, description="the person's score on that scale")


class PatientBase(StrictModel):
    """The plugin-independent part of a patient profile."""

    id: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", description="pseudonymous id (no names)")
    side: Literal["left", "right"] = Field(description="treated side")
    segments: dict[str, float] = Field({}, description="segment lengths [m] (e.g. upper_arm, forearm); robots "
                                                        "with a setting of the same name adapt to them")
    joints: dict[str, JointRom] = Field({}, description="range of motion per robot joint")
    comfort: Comfort = Comfort()
    version: int = Field(1, ge=1, description="the profile's version (an assessment writes the next)")
    assessed: dict[str, str] | None = Field(None, description="how and when its ranges were measured")
    impairment: Impairment | None = Field(None, description="what is treated, and its score on a clinical scale")
    session: str | None = Field(None, pattern=r"^[A-Za-z0-9]+$", description="the session's label (letters and "
                                "digits; a dataset's ses-<label>, else the run's date)")
    outside_rom: Literal["refuse", "nearest"] = Field(
        "refuse", description="a target outside the range: refuse the scenario, or use the nearest admissible point")

    @field_validator("session", mode="before")
    @classmethod
    def _session_label(cls, v):  # (`--set patient.session=3`: YAML reads a number)
        return str(v) if isinstance(v, int) and not isinstance(v, bool) else v

    @model_validator(mode="after")
    def _positive_segments(self) -> PatientBase:
        bad = [k for k, v in self.segments.items() if not v > 0]
        if bad:
            raise ValueError(f"segment lengths must be > 0: {bad}")
        return self


def profile_model(registry) -> type[PatientBase]:
    """The ``patient:`` section's model: the profile, and ``model:`` taking any installed patient plugin's settings."""
    from typing import Optional

    from pydantic import create_model

    from rehabkit.core.scenario.models import plugin_union

    union = plugin_union(registry, "patient")
    if union is None:
        return PatientBase
    return create_model("Patient", __base__=PatientBase,
                        model=(Optional[union], Field(None, description="simulated behaviour")))  # noqa: UP045
