"""The sensor plugin kind: what a sensor is, its settings' base, the instruments it puts in a simulated scene."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field

from rehabkit.core.metric import Metric
from rehabkit.models.strict import StrictModel


@dataclass(frozen=True)
class Instrument:
    """A physical sensing element a sensor plugin needs in the simulated scene.

    Attributes:
        name: Unique name (the backend reads it back by this name).
        kind: ``accelerometer`` (specific force, site frame [m/s²]) or ``gyro`` (angular velocity [rad/s]).
        body: Body it is fixed to.
        position: Where on that body (body frame) [m]; axes aligned with the body's.
    """

    name: str
    kind: Literal["accelerometer", "gyro"]
    body: str
    position: tuple[float, float, float]


class SensorConfig(StrictModel):
    """Base of every sensor plugin's config: each sensor runs at its own rate."""

    rate_hz: float = Field(100.0, gt=0, description="sampling rate [Hz]")


class Sensor(ABC):
    """Reads something at its own rate; readings go to the log and to ``Runner.observations``."""

    rate_hz: float
    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of what run_metrics reports
    blocking: bool = False  # a reading takes longer than a control tick (a camera frame): on a real-time
    #                         backend it is read in a thread of its own (``rehabkit.core.sensor_threads``)

    @abstractmethod
    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Any) -> dict[str, Any]:
        """One reading: name → value (arrays, scalars, or an image as ``HxWx3`` uint8).

        A sensor that locates a task target reports it as ``target_position``
        (robot base frame, [m]); ``None`` when it sees nothing.
        """

    def run_metrics(self, trace: Any = None) -> dict[str, float]:
        """Figures about the whole run (e.g. estimation error), given the run's trace; default none."""
        return {}

    def report(self, metrics: dict[str, float]) -> str | None:
        """A short text report for people (printed by ``rehabkit run``, kept in summary.json); default none."""
        return None

    def instruments(self) -> list[Instrument]:
        """Sensing elements to put in the simulated scene (read with ``backend.read_instrument``)."""
        return []
