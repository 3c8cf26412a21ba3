"""A sensor plugin: the hand's position in the world (a motion-capture marker), with Gaussian noise."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, Metric, Sensor, SensorConfig, hookimpl


class HandPositionConfig(SensorConfig):
    """The marker's noise."""

    noise_mm: float = Field(0.5, ge=0, description="standard deviation of each coordinate's noise [mm]")


class HandPosition(Sensor):
    """Reads the hand position from the joint angles (forward kinematics) and adds the marker's noise."""

    metrics = (Metric("hand_marker_error_rms_mm", "mm", description="RMS distance of the readings from the hand"),)

    def __init__(self, config: HandPositionConfig, context: Context):
        self.noise = config.noise_mm / 1000
        self.robot, self.rng = context.robot, context.rng
        self.errors: list[float] = []

    def read(self, t, q, qd, backend) -> dict[str, np.ndarray]:
        hand = self.robot.ee_world(np.asarray(q)[None])[0]
        noisy = hand + self.rng.normal(0.0, self.noise, 3)
        self.errors.append(float(np.linalg.norm(noisy - hand)))
        return {"hand_world_m": noisy}

    def run_metrics(self, trace) -> dict[str, float]:
        return {"hand_marker_error_rms_mm": 1000 * float(np.sqrt(np.mean(np.square(self.errors or [0.0]))))}


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("hand-position", config=HandPositionConfig, factory=HandPosition)
