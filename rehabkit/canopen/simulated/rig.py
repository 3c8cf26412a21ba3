"""Simulated drives on a robot: one :class:`~rehabkit.canopen.simulated.drive.SimulatedDrive` per joint, all moving one
MuJoCo plant (the robot's model with the run's instruments and a test rig's loads, as the bridge's), and one
:class:`~rehabkit.canopen.simulated.sensor.SimulatedSensor` per instrument.

Each SYNC every drive samples its joint and takes its RPDOs, in node order; then the plant advances one
communication cycle (0x1006) in steps of its own timestep, with the torques the drives latched. So the torque a host
computes from the state of SYNC k drives the plant from SYNC k+1: the one-cycle delay of cyclic synchronous modes.
A drive whose power stage goes off applies its motor's holding brake, where the robot has brakes (as drives control
them). A write of the simulation-only object 0x2001 resets the plant to the start positions written in every drive's
0x2000 (what a test rig's operator does by hand).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import canopen
import numpy as np

from rehabkit.canopen.cia402 import State
from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.simulated.drive import EDS, SYNC_ID, SimulatedDrive
from rehabkit.canopen.simulated.sensor import SimulatedSensor
from rehabkit.hardware.plant import MujocoPlant

SYNC_LOST = 0x8100  # CiA 301: communication error (here: the SYNC stopped coming)


class _PlantJoint:
    """Joint ``i`` of the rig's plant, as its drive sees it."""

    def __init__(self, rig: DriveRig, i: int):
        self.rig, self.i = rig, i

    def apply(self, torque: float) -> None:
        self.rig.tau[self.i] = torque

    def read(self) -> tuple[float, float, float]:
        r, i = self.rig, self.i
        return float(r.q[i]), float(r.qd[i]), float(r.tau[i])


class DriveRig:
    """``plant``'s joints each on a simulated drive (``nodes``: node ids, ``units``: each drive's) on ``network``;
    ``clocked``: the drives' heartbeats on the SYNC clock (a lock-step bus)."""

    def __init__(self, network: canopen.Network, plant: MujocoPlant, nodes: Sequence[int],
                 units: Sequence[DriveUnits], clocked: bool = False, eds=EDS, sensors: Sequence[int] = ()):
        self.plant = plant
        n = plant.joints
        self.q, self.qd, self.tau = np.zeros(n), np.zeros(n), np.zeros(n)
        self.drives = [SimulatedDrive(network, node, _PlantJoint(self, i), u, eds, own_sync=False, clocked=clocked)
                       for i, (node, u) in enumerate(zip(nodes, units, strict=True))]
        for d in self.drives:
            d.node.add_write_callback(self._on_write)
        self._readings = np.zeros(3 * len(sensors))  # the plant's instruments, read once a cycle, in order
        self.sensors = [SimulatedSensor(network, node, lambda k=k: self._readings[3 * k : 3 * k + 3],
                                        clocked=clocked) for k, node in enumerate(sensors)]
        network.subscribe(SYNC_ID, self.on_sync)
        self.substeps, self.period = 1, plant.timestep
        self.cycles = 0
        self.last_sync: float | None = None  # [s, monotonic] (real time: the SYNC watchdog's)
        self.sync_timeout_s = 0.010  # the drives' SYNC watchdog (see watch_sync)
        self._watching = threading.Event()

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if index == 0x2001:
            q0 = np.array([d.node.sdo[0x2000].raw / (d.units.counts_per_rad * d.units.direction) for d in self.drives])
            self.reset(q0)
        elif index == 0x1006:
            self.period = od.decode_raw(data) * 1e-6
            self.substeps = max(1, round(self.period / self.plant.timestep))

    def reset(self, q0: np.ndarray) -> None:
        """The plant at rest at ``q0``; each drive's own loop tuned to its joint's inertia there."""
        self.plant.reset(q0)
        self.tau[:] = 0.0
        self._read()
        for d, m in zip(self.drives, self.plant.joint_inertia(), strict=True):
            d.inertia = float(m)

    def _read(self) -> None:
        self.q[:], self.qd[:] = self.plant.read()

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0) -> None:
        """Every drive samples and latches, then the plant runs one cycle with the latched torques."""
        self.last_sync = time.monotonic()
        for i, d in enumerate(self.drives):
            on = d.machine.torque_on
            if d.silent:  # cut off the bus: no SYNC reaches it; its SYNC watchdog, then its reaction, on its own clock
                d.unheard += 1
                if d.unheard * self.period > self.sync_timeout_s:
                    d.connection_lost(SYNC_LOST)
                d.react()
            else:
                d.on_sync(can_id, data, timestamp)
            self._brake_if_off(i, on)
        if self.sensors:
            self._readings[:] = self.plant.read_instruments()
            for s in self.sensors:
                s.on_sync(can_id, data, timestamp)
        if not any(d.syncs for d in self.drives):  # (no drive operational yet: the plant waits)
            return
        self._advance()
        self.cycles += 1

    def watch_sync(self, timeout_s: float = 0.010) -> threading.Thread:
        """In real time: a thread telling every drive still enabled that its connection is lost (0x8100: their EMCYs,
        their reactions as 0x6007 says) once the SYNC has not come for ``timeout_s``; the drives' reactions and quick
        stops then run on their own clock (stopped by :meth:`stop_watching`)."""
        self.sync_timeout_s = timeout_s
        thread = threading.Thread(target=self._watch, name="sync-watchdog", daemon=True)
        thread.start()
        return thread

    def stop_watching(self) -> None:
        self._watching.set()

    def _watch(self) -> None:
        while not self._watching.wait(self.period):
            last = self.last_sync
            if last is None or time.monotonic() - last <= self.sync_timeout_s:
                continue
            for d in self.drives:  # (a drive already stopping, or stopped, carries on with that)
                if d.machine.state is State.OPERATION_ENABLED:
                    d.connection_lost(SYNC_LOST)
            while not self._watching.wait(self.period):  # the reactions, one cycle at a time, without a SYNC
                if self.last_sync != last:  # (the SYNC came back: the drives take it from there)
                    break
                if any(d.machine.torque_on for d in self.drives):  # (none driving: the plant waits for the SYNC)
                    self.coast()

    def coast(self) -> None:
        """A cycle without SYNC (the drives' reactions on their own clock): each drive's reaction, the plant runs."""
        for i, d in enumerate(self.drives):
            on = d.machine.torque_on
            d.react()
            self._brake_if_off(i, on)
        self._advance()

    def _brake_if_off(self, i: int, was_on: bool) -> None:
        """Drive ``i``'s power stage went off: it applies its motor's brake (where the robot has them)."""
        if was_on and not self.drives[i].machine.torque_on:
            self.plant.brake([i])

    def _advance(self) -> None:
        """The plant through one cycle with the torques the drives latched."""
        self.plant.apply(np.clip(self.tau, -self.plant.effort, self.plant.effort))
        for _ in range(self.substeps):
            self.plant.advance()
        self._read()
