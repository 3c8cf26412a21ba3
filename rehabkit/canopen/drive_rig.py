"""Simulated drives on a robot: one :class:`~rehabkit.canopen.sim_drive.SimulatedDrive` per joint, all moving one
MuJoCo plant (the robot's model with the run's instruments and a test rig's loads, as the bridge's).

Each SYNC every drive samples its joint and takes its RPDOs, in node order; then the plant advances one
communication cycle (0x1006) in steps of its own timestep, with the torques the drives latched. So the torque a host
computes from the state of SYNC k drives the plant from SYNC k+1: the one-cycle delay of cyclic synchronous modes.
A write of the simulation-only object 0x2001 resets the plant to the start positions written in every drive's
0x2000 (what a test rig's operator does by hand).
"""

from __future__ import annotations

from collections.abc import Sequence

import canopen
import numpy as np

from rehabkit.canopen.sim_drive import EDS, SYNC_ID, DriveUnits, SimulatedDrive
from rehabkit.hardware.plant import MujocoPlant

VELOCITY_BANDWIDTH = 100.0  # [rad/s] the drives' velocity loops (quick stops), tuned to each joint's inertia


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
                 units: Sequence[DriveUnits], clocked: bool = False, eds=EDS):
        self.plant = plant
        n = plant.joints
        self.q, self.qd, self.tau = np.zeros(n), np.zeros(n), np.zeros(n)
        self.drives = [SimulatedDrive(network, node, _PlantJoint(self, i), u, eds, own_sync=False, clocked=clocked)
                       for i, (node, u) in enumerate(zip(nodes, units, strict=True))]
        for d in self.drives:
            d.node.add_write_callback(self._on_write)
        network.subscribe(SYNC_ID, self.on_sync)
        self.substeps = 1
        self.cycles = 0

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if index == 0x2001:
            q0 = np.array([d.node.sdo[0x2000].raw / (d.units.counts_per_rad * d.units.direction) for d in self.drives])
            self.reset(q0)
        elif index == 0x1006:
            period = od.decode_raw(data) * 1e-6
            self.substeps = max(1, round(period / self.plant.timestep))

    def reset(self, q0: np.ndarray) -> None:
        """The plant at rest at ``q0``; each drive's velocity loop tuned to its joint's inertia there."""
        self.plant.reset(q0)
        self.tau[:] = 0.0
        self._read()
        for d, m in zip(self.drives, self.plant.joint_inertia(), strict=True):
            d.velocity_gain = VELOCITY_BANDWIDTH * float(m)

    def _read(self) -> None:
        self.q[:], self.qd[:] = self.plant.read()

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0) -> None:
        """Every drive samples and latches, then the plant runs one cycle with the latched torques."""
        for d in self.drives:
            d.on_sync(can_id, data, timestamp)
        if not any(d.syncs for d in self.drives):  # (no drive operational yet: the plant waits)
            return
        self.plant.apply(np.clip(self.tau, -self.plant.effort, self.plant.effort))
        for _ in range(self.substeps):
            self.plant.advance()
        self._read()
        self.cycles += 1
