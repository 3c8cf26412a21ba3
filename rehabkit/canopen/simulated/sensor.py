"""A simulated three-axis sensor on a CANopen network (a generic CiA 404 measuring device): a run's instrument — a
force-torque sensor's force, an accelerometer's acceleration — read from the plant at each SYNC and sent in a TPDO,
each axis an INTEGER16 process value (0x7130) in units of the device's scale (0x2100: 0.01)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import canopen
import numpy as np

from rehabkit.canopen.simulated.node import SYNC_ID, SimulatedNode

EDS = Path(__file__).resolve().parents[1] / "eds" / "cia404_sensor.eds"
INPUTS = ((0x7130, 1), (0x7130, 2), (0x7130, 3))


class SimulatedSensor(SimulatedNode):
    """Sensor ``node_id`` on ``network`` reading ``read()`` (3 values) at each SYNC (see the module's doc)."""

    def __init__(self, network: canopen.Network, node_id: int, read: Callable[[], np.ndarray], eds: Path = EDS,
                 clocked: bool = False):
        super().__init__(network, node_id, eds, INPUTS, clocked=clocked)
        self.read = read
        self.scale = float(self.node.value(0x2100))
        self.boot()

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0) -> None:
        """A SYNC: the inputs sampled, the TPDO sent."""
        if not self.begin_cycle() or self.nmt.state != "OPERATIONAL":
            return
        values = np.clip(np.rint(np.asarray(self.read(), float) / self.scale), -32768, 32767)
        for key, v in zip(INPUTS, values, strict=True):
            self.values[key] = int(v)
        self.send_tpdos()
