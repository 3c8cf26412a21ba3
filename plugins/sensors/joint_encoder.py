"""Joint encoders: quantised joint positions with optional noise — a revolute joint's angle in radians (a rotary
encoder's counts per revolution), a prismatic joint's position in metres (a linear encoder's counts per metre)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
from pydantic import Field

from rehabkit.plugin import Backend, Context, Sensor, SensorConfig, SettingError, hookimpl


class JointEncoderConfig(SensorConfig):
    """Encoder resolution and noise."""

    counts_per_rev: int = Field(4096, gt=0, description="counts per revolution of a revolute joint (after gearing)")
    counts_per_m: int = Field(100_000, gt=0, description="counts per metre of a prismatic joint's travel (a linear "
                              "encoder; the default: 10 µm)")
    noise_counts: float = Field(0.0, ge=0, description="standard deviation of additive noise [counts]")
    joints: list[str] | None = Field(None, description="joints to read, passive ones included (default: the driven)")


class JointEncoder(Sensor):
    """Joint positions as encoders read them: quantised to whole counts, optionally noisy. A reading holds
    ``position_rad`` (the revolute joints read, in radians) and, where it reads prismatic joints, ``position_m``
    (theirs, in metres): each joint in its own SI unit, logged as degrees and metres."""

    def __init__(self, config: JointEncoderConfig, context: Context):
        model = context.robot.model
        self.noise = config.noise_counts
        self.rng = context.rng
        self.joints = config.joints
        self.names = config.joints or model.joint_names
        if self.joints:
            known = model.joint_names + model.passive_joints
            unknown = [j for j in self.joints if j not in known]
            if unknown:
                raise SettingError("joints", f"unknown joint(s) {unknown}; the robot has {known}")
        kinds = {j.get("name"): j.get("type", "hinge") for j in ET.fromstring(model.mjcf).iter("joint")}
        slides = np.array([kinds.get(n, "hinge") == "slide" for n in self.names], bool)
        self.turning, self.sliding = np.flatnonzero(~slides), np.flatnonzero(slides)
        # counts per SI unit of each joint read (per radian, per metre) and the value of a count
        self.per_unit = np.where(slides, float(config.counts_per_m), config.counts_per_rev / (2 * np.pi))
        self.step = np.where(slides, 1.0 / config.counts_per_m, 2 * np.pi / config.counts_per_rev)

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, np.ndarray]:
        if self.joints:
            q = backend.joint_positions(self.joints)
        counts = np.rint(q * self.per_unit)  # a new array each reading: readings are kept
        if self.noise:
            counts += np.rint(self.rng.normal(0.0, self.noise, size=q.shape))
        value = counts * self.step
        if not len(self.sliding):
            return {"position_rad": value}
        out = {"position_m": value[self.sliding]}
        if len(self.turning):
            out["position_rad"] = value[self.turning]
        return out

    def channels(self, key: str, width: int) -> list[str] | None:
        """A joint's name per value: the revolute joints' of ``position_rad``, the prismatic ones' of
        ``position_m``."""
        which = {"position_rad": self.turning, "position_m": self.sliding}.get(key)
        names = [self.names[i] for i in which] if which is not None else None
        return names if names is not None and width == len(names) else None


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("joint-encoder", config=JointEncoderConfig, factory=JointEncoder)
