"""Simulated drives on a robot: one :class:`~rehabkit.canopen.simulated.drive.SimulatedDrive` per joint (each serving
the generic servo's EDS or its own vendor's EDS/DCF), all moving one MuJoCo plant (the robot's model with the run's
instruments and a test rig's loads, as the bridge's), and one :class:`~rehabkit.canopen.simulated.sensor.
SimulatedSensor` per instrument.

Each SYNC every drive samples its joint and takes its RPDOs, in node order; then the plant advances one
communication cycle (the drives' cycle: 0x1006, else 0x60C2, else the plant's step) in steps of its own timestep,
with the torques the drives latched. So the torque a host computes from the state of SYNC k drives the plant from
SYNC k+1: the one-cycle delay of cyclic synchronous modes. A drive whose power stage goes off applies its motor's
holding brake, where the robot has brakes (as drives control them). A write of the simulation-only object 0x5FFF
resets the plant to the start positions written in every drive's 0x5FFE (what a test rig's operator does by hand).

The drives' watchdogs (heartbeat consumer, SYNC watchdog) go on their own clocks on a lock-step bus; in real time on
the wall clock, polled by the rig's watchdog thread (:meth:`DriveRig.watch_sync`), which also runs the drives'
reactions (a quick stop, a fault reaction) on their own while the SYNC does not come. In real time they go on when
each frame arrived and judge once the reader has caught up (:mod:`~rehabkit.canopen.simulated.arrivals`: this
process's own stalls are not the host's), and the rig keeps its figures (:meth:`DriveRig.figures`): the SYNCs, the
largest gap between two as they arrived while a drive was powered, those handled a cycle or more after they arrived,
the watchdog thread's worst wake-up, how often it waited for the reader and what the watchdogs fired for.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from pathlib import Path

import canopen
import numpy as np

from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS
from rehabkit.canopen.simulated.arrivals import Arrivals
from rehabkit.canopen.simulated.drive import EDS, PLACE, START_POSITION, SYNC_ID, SYNC_LOST, SimulatedDrive
from rehabkit.canopen.simulated.sensor import SimulatedSensor
from rehabkit.canopen.simulated.watchdogs import Watchdog
from rehabkit.hardware.plant import MujocoPlant

__all__ = ["SYNC_LOST", "DriveRig"]
# a reader behind this long without catching up once (this process can no longer keep up with its bus): the
# watchdogs judge on what it has had. Not the SYNC timeout: a reader starved by the OS for longer than that (48 ms,
# measured with one core busy and the drives in the ordinary class) would blame the host for its own stall
READER_BEHIND_S = 1.0


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
    """``plant``'s joints each on a simulated drive (``nodes``: node ids, ``units``: each drive's, ``eds``: one EDS
    or DCF for all or one per drive) on ``network``; ``clocked``: the drives' heartbeats and watchdogs on their own
    clocks (a lock-step bus)."""

    def __init__(self, network: canopen.Network, plant: MujocoPlant, nodes: Sequence[int],
                 units: Sequence[DriveUnits], clocked: bool = False, eds: Path | str | Sequence[Path | str] = EDS,
                 sensors: Sequence[int] = ()):
        self.plant, self.network = plant, network
        n = plant.joints
        self.q, self.qd, self.tau = np.zeros(n), np.zeros(n), np.zeros(n)
        files = list(eds) if isinstance(eds, (list, tuple)) else [eds] * len(nodes)  # (one for all, or each its own)
        step_us = max(1, round(plant.timestep * 1e6))
        self.drives = [SimulatedDrive(network, node, _PlantJoint(self, i), u, Path(path), own_sync=False,
                                      clocked=clocked, cycle_us=step_us)
                       for i, (node, u, path) in enumerate(zip(nodes, units, files, strict=True))]
        self._powered = [False] * n  # each drive's power stage at the last cycle (its brake when it goes off)
        for d in self.drives:
            d.node.add_write_callback(self._on_write)
        self._readings = np.zeros(3 * len(sensors))  # the plant's instruments, read once a cycle, in order
        self.sensors = [SimulatedSensor(network, node, lambda k=k: self._readings[3 * k : 3 * k + 3],
                                        clocked=clocked) for k, node in enumerate(sensors)]
        network.subscribe(SYNC_ID, self.on_sync)
        self.substeps, self.period = 1, plant.timestep
        self.cycles = 0
        self.last_sync: float | None = None  # [s, monotonic] when the last SYNC arrived (real time: the watchdog's)
        self.sync_timeout_s = SYNC_TIMEOUT_MS * 1e-3  # the drives' SYNC watchdog (see watch_sync)
        self._lock = threading.RLock()  # (real time: the bus's thread and the watchdog's)
        self._watchdog: Watchdog | None = None
        self._arrivals: Arrivals | None = None
        self._behind_since: float | None = None  # (the reader behind since, as the watchdog found it)
        self._armed = False  # a drive's power stage was on at the last SYNC (its gap to the next one counts)
        self.max_gap = self.max_delay = 0.0  # [s] SYNC to SYNC as they arrived, armed; arrival to handling
        self.late = self.waited = 0  # SYNCs handled a cycle or more after they arrived; watchdog rounds deferred

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if index == PLACE:
            q0 = np.array([d.values[START_POSITION, 0] / (d.units.position * d.units.direction) for d in self.drives])
            self.reset(q0)
        elif index in (0x1006, 0x60C2):  # (the drives' cycle: the plant's steps per cycle)
            self.period = self.drives[0].cycle_us * 1e-6
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
        with self._lock:
            now = time.monotonic()
            at = self._arrivals.at(timestamp) if self._arrivals is not None else now
            if self._armed and self.last_sync is not None:
                self.max_gap = max(self.max_gap, at - self.last_sync)
            self.max_delay = max(self.max_delay, now - at)
            self.late += now - at >= self.period
            self.last_sync = at
            for d in self.drives:
                if d.silent:  # cut off the bus: no SYNC reaches it; its watchdog, then its reaction, on its own clock
                    d.react()
                else:
                    d.on_sync(can_id, data, timestamp, at)
            self._armed = any(d.machine.torque_on for d in self.drives)
            self._brakes()
            if self.sensors:
                self._readings[:] = self.plant.read_instruments()
                for s in self.sensors:
                    s.on_sync(can_id, data, timestamp)
            if not any(d.syncs for d in self.drives):  # (no drive operational yet: the plant waits)
                return
            self._advance()
            self.cycles += 1

    def watch_sync(self, timeout_s: float = SYNC_TIMEOUT_MS * 1e-3) -> threading.Thread:
        """In real time: a thread polling every drive's watchdogs on the wall clock each plant period — its
        heartbeat consumer, its SYNC watchdog (``timeout_s``: 0x8100, the reaction 0x6007 says) — and, while the
        SYNC does not come and a drive's power stage is on, running the drives' reactions on their own clock (stopped
        by :meth:`stop_watching`). The watchdogs go on when frames arrived, judged once the reader has caught up."""
        self.sync_timeout_s = timeout_s
        self._arrivals = Arrivals(self.network)
        for d in (*self.drives, *self.sensors):
            d.arrival = self._arrivals.at
        for d in self.drives:
            d.sync_watchdog.timeout_s = timeout_s
        self._watchdog = Watchdog(self._watch, lambda: self.period, "drive-watchdog").start()
        return self._watchdog.thread

    def stop_watching(self) -> None:
        if self._watchdog is not None:
            self._watchdog.stop()

    def figures(self) -> dict[str, float | list]:
        """The drives' side of the run: SYNCs, the largest gap between two as they arrived while a drive was powered
        [ms], SYNCs handled a cycle or more after they arrived and the longest such wait [ms], the watchdog thread's
        worst wake-up past due [ms] and the rounds it waited for the reader, what the watchdogs fired for (per drive:
        0x8100 SYNC, 0x8130 the host's heartbeat, with the silence [ms])."""
        fired = [(d.node.id, code, round(s * 1e3, 1)) for d in self.drives
                 for code, said in ((0x8100, d.sync_watchdog.fired), (0x8130, d.consumer.fired)) for s in said]
        woke = self._watchdog.woke_late if self._watchdog is not None else 0.0
        return {"cycles": self.cycles, "max_sync_gap_ms": self.max_gap * 1e3, "late_syncs": self.late,
                "max_sync_delay_ms": self.max_delay * 1e3, "watchdog_woke_late_ms": woke * 1e3,
                "watchdog_waited": self.waited, "fired": fired}

    def _watch(self) -> None:
        now = time.monotonic()
        if self._arrivals is not None and not self._arrivals.caught_up():  # frames came that it has not yet had:
            self.waited += 1  # judged once it has (the bus is alive meanwhile: its frames wait in the socket)
            self._behind_since = self._behind_since or now
            if now - self._behind_since <= READER_BEHIND_S:
                return
        self._behind_since = None
        with self._lock:
            for node in (*self.drives, *self.sensors):
                node.poll()
            last = self.last_sync
            late = last is not None and time.monotonic() - last > self.sync_timeout_s
            if late and any(d.machine.torque_on for d in self.drives):  # (none driving: the plant waits)
                self.coast()

    def coast(self) -> None:
        """A cycle without SYNC (the drives' reactions on their own clock): each drive's reaction, the plant runs."""
        with self._lock:
            for d in self.drives:
                d.react()
            self._brakes()
            self._advance()

    def _brakes(self) -> None:
        """A drive whose power stage went off since the last cycle applies its motor's brake (where the robot has
        them)."""
        for i, d in enumerate(self.drives):
            on = d.machine.torque_on
            if self._powered[i] and not on:
                self.plant.brake([i])
            self._powered[i] = on

    def _advance(self) -> None:
        """The plant through one cycle with the torques the drives latched."""
        self.plant.apply(np.clip(self.tau, -self.plant.effort, self.plant.effort))
        for _ in range(self.substeps):
            self.plant.advance()
        self._read()
