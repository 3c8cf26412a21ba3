"""Incremental joint encoders: quantised joint angles with optional noise."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit import hookimpl
from rehabkit.plugin import Backend, Context, Sensor, SensorConfig, SettingError


class JointEncoderConfig(SensorConfig):
    """Encoder resolution and noise."""

    counts_per_rev: int = Field(4096, gt=0, description="counts per joint revolution (after gearing)")
    noise_counts: float = Field(0.0, ge=0, description="standard deviation of additive noise [counts]")
    joints: list[str] | None = Field(None, description="joints to read, passive ones included (default: the driven)")


class JointEncoder(Sensor):
    """Joint angles as an encoder reads them: quantised to whole counts, optionally noisy."""

    def __init__(self, config: JointEncoderConfig, context: Context):
        self.step = 2 * np.pi / config.counts_per_rev
        self.per_rad = config.counts_per_rev / (2 * np.pi)
        self.noise = config.noise_counts
        self.rng = context.rng
        self.joints = config.joints
        self.names = config.joints or context.robot.model.joint_names
        if self.joints:
            model = context.robot.model
            known = model.joint_names + model.passive_joints
            unknown = [j for j in self.joints if j not in known]
            if unknown:
                raise SettingError("joints", f"unknown joint(s) {unknown}; the robot has {known}")

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, np.ndarray]:
        if self.joints:
            q = backend.joint_positions(self.joints)
        counts = np.rint(q * self.per_rad)  # a new array each reading: readings are kept
        if self.noise:
            counts += np.rint(self.rng.normal(0.0, self.noise, size=q.shape))
        counts *= self.step
        return {"position_rad": counts}

    def channels(self, key: str, width: int) -> list[str] | None:
        """A joint's name per angle."""
        return list(self.names) if width == len(self.names) else None


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("joint-encoder", config=JointEncoderConfig, factory=JointEncoder)
