"""The sensor plugin kind: what a sensor is, its settings' base, the instruments it puts in a simulated scene."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field

from rehabkit.core.kinds.metric import Metric
from rehabkit.core.kinds.run_state import RunState
from rehabkit.core.kinds.trace import Trace
from rehabkit.models.strict import StrictModel


@dataclass(frozen=True)
class Instrument:
    """A physical sensing element a sensor plugin needs in the simulated scene.

    Attributes:
        name: Unique name (the backend reads it back by this name).
        kind: ``accelerometer`` (specific force, site frame [m/s²]), ``gyro`` (angular velocity [rad/s]),
            ``force`` [N] or ``torque`` [N·m] (what the body beyond the sensor exerts on the robot, site frame).
        body: Body it is fixed to.
        position: Where on that body (body frame) [m]; axes aligned with the body's.
        mount: ``force``/``torque``: the body beyond the sensor (a handle, a cuff), made at ``position`` on ``body``
            and weighing 1 g; what pushes on it (a strap, a test rig's load) is what the sensor reads. Instruments
            naming the same mount share it.
        bias: A simulated sensor's constant offset, added to every reading (a real one brings its own).
        noise: A simulated sensor's white noise, standard deviation per axis.
    """

    name: str
    kind: Literal["accelerometer", "gyro", "force", "torque"]
    body: str
    position: tuple[float, float, float]
    mount: str | None = None
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    noise: float = 0.0

    @property
    def simulated_error(self) -> bool:
        return self.noise > 0 or any(self.bias)


INSTRUMENT_DIM = 3  # every instrument reads a 3-vector


class SensorConfig(StrictModel):
    """Base of every sensor plugin's config: each sensor runs at its own rate, set here and nowhere else (the run
    reads it from the sensor's section; a sensor that needs it reads ``config.rate_hz``). A sensor's settings
    model derives from this one, giving its own default where another suits it."""

    rate_hz: float = Field(100.0, gt=0, description="sampling rate [Hz]")


@dataclass(frozen=True)
class Reading:
    """A sensor's latest reading, as a plugin gets it by the sensor's name (``Context.reading``): ``values`` is what
    its ``read`` returned, taken at ``t`` [s] on the run's clock; its vectors are in ``frame`` (the sensor's
    declared :attr:`Sensor.frame`; ``None`` where its values are not spatial, e.g. joint angles)."""

    sensor: str
    t: float
    values: dict[str, Any]
    frame: str | None


class Sensor(RunState, ABC):
    """Reads something at its own rate (its config's ``rate_hz``, :class:`SensorConfig`); readings go to the log and
    to the run's readings (``Context.reading``)."""

    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of what run_metrics reports
    requires: ClassVar[tuple[type, ...]] = ()  # capabilities needed of the robot or backend (core.kinds.capabilities)
    frame: str | None = None  # the frame its vector readings are in (e.g. "robot base", a body's name); None: none
    blocking: bool = False  # a reading takes longer than a control tick (a camera frame): on a real-time
    #                         backend it is read in a thread of its own (``rehabkit.core.run.sensor_threads``)

    @abstractmethod
    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Any) -> dict[str, Any]:
        """One reading: name → value (arrays, scalars, or an image as ``HxWx3`` uint8).

        A sensor that locates a task target reports it as ``target_position``
        (robot base frame, [m]); ``None`` when it sees nothing.
        """

    def run_metrics(self, trace: Trace) -> dict[str, float]:
        """Figures about the whole run (e.g. estimation error), given the run's trace; default none."""
        return {}

    def channels(self, key: str, width: int) -> list[str] | None:
        """What each of the ``width`` values of the vector reading ``key`` is (a joint's name, an axis), for the
        log's series names; default: ``x y z`` for a 3-vector of a spatial sensor (:attr:`frame` set), else none
        (numbered)."""
        return ["x", "y", "z"] if width == 3 and self.frame is not None else None

    def report(self, metrics: dict[str, float]) -> str | None:
        """A short text report for people (printed by ``rehabkit run``, kept in summary.json); default none."""
        return None

    def instruments(self) -> list[Instrument]:
        """Sensing elements to put in the simulated scene (read with ``backend.read_instrument``)."""
        return []


class InteractionForceSensor(Sensor):
    """A sensor of the force between the person and the robot (a force-torque sensor at a handle or cuff). When
    ``interaction`` is set, the runner reads it every control step and the safety envelope's interaction-force limit
    checks it, on every backend that reads its instruments (a simulation, or a robot link)."""

    interaction: bool = True

    @abstractmethod
    def interaction_force(self, t: float, backend: Any) -> np.ndarray:
        """The force the person (or a rig) puts on the robot now [N], 3 values; called every control step."""

    def joint_torque(self, q: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """The joint torques [N·m] that ``force`` (as :meth:`interaction_force` gave it) exerts on the robot at
        posture ``q``: where it acts and in which axes (a retreat moves away along it); default None (unknown)."""
        return None
