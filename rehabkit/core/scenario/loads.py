"""Test-rig loads in the scene (``world.loads``): a known force pushed on a robot body, the way a safety skill's
validation protocol pushes on a handle with a force gauge or hangs a weight from it."""

# (no `from __future__ import annotations`: pydantic would evaluate each field's annotation from its text, as
# each model and every subclass is built, ~1 ms a module; a model's own name in a method's is quoted)
from pydantic import Field, model_validator

from rehabkit.models.strict import StrictModel

Vec3 = tuple[float, float, float]


class Load(StrictModel):
    """A force on a body of the scene, world frame: zero until ``start_s``, rising linearly over ``ramp_s`` to
    ``force_n``, held until ``release_s``. Simulated wherever the robot is (the MuJoCo scene, or the MuJoCo plant
    behind a hardware link's bridge); on a real robot the rig itself pushes.

    With ``stiffness_n_m`` the rig pushes through a spring, as a person's arm or a pusher with a load cell does: its
    far end advances along the force so that on a body held still the force is the profile above, and a body that
    gives way along it by d is pushed k·d less (never pulled). Without it the force is applied whatever the body
    does (a hanging weight)."""

    name: str
    body: str = Field(description="the body pushed: a robot body, or a force-torque sensor's mount (its name)")
    force_n: Vec3 = Field(description="the full force, world frame [N]")
    start_s: float = Field(0.0, ge=0, description="when the push begins")
    ramp_s: float = Field(0.0, ge=0, description="how long it takes to reach the full force (0: at once)")
    release_s: float | None = Field(None, gt=0, description="when it stops (default: never)")
    stiffness_n_m: float | None = Field(None, gt=0, description="push through a spring of this stiffness [N/m]: "
                                        "the force falls as the body gives way (default: a set force)")

    @model_validator(mode="after")
    def _ordered(self) -> 'Load':
        if self.release_s is not None and self.release_s <= self.start_s:
            raise ValueError(f"load '{self.name}': release_s ({self.release_s:g}) must come after start_s "
                             f"({self.start_s:g})")
        return self

    def at(self, t: float) -> float:
        """The share of the full force applied at time ``t`` [s]."""
        if t < self.start_s or (self.release_s is not None and t >= self.release_s):
            return 0.0
        return 1.0 if self.ramp_s == 0 else min(1.0, (t - self.start_s) / self.ramp_s)
