"""A simulated CiA 402 servo drive on a CANopen network: what stands in for a joint's drive without the robot.

A ``canopen.LocalNode`` serves the generic servo's EDS (its SDO server, NMT slave and EMCY producer are canopen's);
what the library leaves to the drive is here: the 402 state machine (:class:`~rehabkit.canopen.cia402.Drive402`)
moved by the controlword the master maps into an RPDO, and, on each SYNC while OPERATIONAL, the RPDOs taken in, the
joint driven (cyclic synchronous torque: the target torque in per mille of the rated torque 0x6076, applied only
while the power stage is on), and the TPDOs sent with the joint's state in the drive's units. The PDO maps are the
master's: written by SDO into the drive's dictionary and read back from it at the first SYNC after they change.
A fault (:meth:`SimulatedDrive.fault`) sends its EMCY and takes the state machine through its reaction; so does a
master's heartbeat the drive is told to watch (0x1016) going silent for longer than its consumer time, on the drive's
own clock: the SYNCs it has seen times the communication cycle period (0x1006), so a lock-step bus decides it the same
way every run. Its own heartbeat (0x1017) is canopen's NMT slave's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import canopen

from rehabkit.canopen.cia402 import Drive402

EDS = Path(__file__).resolve().parent / "eds" / "cia402_servo.eds"
SYNC_ID = 0x80
HEARTBEAT_LOST = 0x8130  # CiA 301/402 error code: life guard error or heartbeat error


class Joint(Protocol):
    """The joint a drive moves: ``apply`` a torque [N·m], ``read`` its position [rad], velocity [rad/s] and the torque
    it applies [N·m]."""

    def apply(self, torque: float) -> None: ...

    def read(self) -> tuple[float, float, float]: ...


@dataclass(frozen=True)
class DriveUnits:
    """The drive's units against SI: encoder counts per radian at the joint, the rated torque [N·m] its per mille
    values refer to, and the direction (+1/-1) of its positive sense at the joint."""

    counts_per_rad: float = 4096 / (2 * 3.141592653589793)
    rated_torque_nm: float = 10.0
    direction: int = 1


class SimulatedDrive:
    """Drive ``node_id`` on ``network`` moving ``joint`` (see the module's doc)."""

    def __init__(self, network: canopen.Network, node_id: int, joint: Joint, units: DriveUnits = DriveUnits(),
                 eds: Path = EDS):
        self.node = canopen.LocalNode(node_id, str(eds))
        network.add_node(self.node)
        self.joint, self.units = joint, units
        self.machine = Drive402(quick_stop_option=self.node.sdo[0x605A].raw)
        self.node.sdo[0x6076].raw = round(units.rated_torque_nm * 1e3)  # [mN·m], as the profile gives it
        self._maps_changed = True
        self.node.add_write_callback(self._on_write)
        network.subscribe(SYNC_ID, self._on_sync)
        network.subscribe(0x000, self._on_nmt)
        self.syncs = 0
        self._heard: dict[int, int] = {}  # a watched node → when its heartbeat came last [µs, the drive's clock]
        self._watch: dict[int, int] = {}  # a watched node → its consumer time [µs]
        self._network = network
        self._publish()

    @property
    def clock(self) -> int:
        """The drive's time [µs, exact]: SYNCs seen times the communication cycle period."""
        return self.syncs * self.node.sdo[0x1006].raw

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if 0x1400 <= index <= 0x1BFF:  # the master (re)configures a PDO: its maps read again, once it is written
            self._maps_changed = True
        elif index == 0x605A:
            self.machine.quick_stop_option = od.decode_raw(data)
        elif index == 0x1016 and subindex > 0:  # watch a node's heartbeat: (node id << 16) | consumer time [ms]
            value = od.decode_raw(data)
            node, ms = value >> 16 & 0x7F, value & 0xFFFF
            if node and ms:
                self._watch[node], self._heard[node] = ms * 1000, self.clock
                self._network.subscribe(0x700 + node, self._on_heartbeat)

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._heard[can_id - 0x700] = self.clock

    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        # the PDO maps the master wrote take effect as the node enters OPERATIONAL (NMT start: command 1, for this
        # node or all), before the first RPDO of the cycle arrives
        if len(data) == 2 and data[0] == 1 and data[1] in (0, self.node.id) and self._maps_changed:
            self._take_maps()

    def _take_maps(self) -> None:
        self.node.rpdo.read(from_od=False)
        self.node.tpdo.read(from_od=False)
        self.node.rpdo.subscribe()
        self._maps_changed = False

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        if self.node.nmt.state != "OPERATIONAL":  # PDOs only in OPERATIONAL (CiA 301)
            return
        if self._maps_changed:  # (a map changed while OPERATIONAL: taken at the next cycle)
            self._take_maps()
        self.syncs += 1
        for node, limit in self._watch.items():
            if self.clock - self._heard[node] > limit and self.machine.fault_code != HEARTBEAT_LOST:
                self.fault(HEARTBEAT_LOST)  # (the master's heartbeat silent: the drive stops on its own)
        for pdo in self.node.rpdo.map.values():
            if pdo.enabled and pdo.is_received:
                for var in pdo:  # (into the dictionary, as a drive's own are)
                    self.node.set_data(var.index, var.subindex, var.od.encode_raw(var.raw), check_writable=False)
        self.machine.write(self.node.sdo[0x6040].raw)
        target = self.node.sdo[0x6071].raw * 1e-3 * self.units.rated_torque_nm * self.units.direction
        self.joint.apply(target if self.machine.torque_on else 0.0)
        self._publish()
        for pdo in self.node.tpdo.map.values():
            if pdo.enabled:
                for var in pdo:
                    var.raw = var.od.decode_raw(self.node.get_data(var.index, var.subindex, check_readable=False))
                pdo.transmit()

    def _publish(self) -> None:
        """The drive's state into its dictionary: statusword, error code, actual position, velocity and torque."""
        q, qd, tau = self.joint.read()
        u, sd = self.units, self.node.sdo
        sd[0x6041].raw = self.machine.statusword
        sd[0x603F].raw = self.machine.fault_code
        sd[0x6064].raw = round(u.direction * q * u.counts_per_rad)
        sd[0x606C].raw = round(u.direction * qd * u.counts_per_rad)
        sd[0x6077].raw = max(-32768, min(32767, round(u.direction * tau / u.rated_torque_nm * 1e3)))

    def fault(self, code: int, register: int = 0x01) -> None:
        """The drive detects a fault (``code``: its CiA 402 error code): EMCY sent, the state machine's reaction."""
        self.machine.fault(code)
        self.node.emcy.send(code, register)
        self._publish()
