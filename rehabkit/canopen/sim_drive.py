"""A simulated CiA 402 servo drive on a CANopen network: what stands in for a joint's drive without the robot.

A ``canopen.LocalNode`` serves the generic servo's EDS (its SDO server, NMT slave and EMCY producer are canopen's);
what the library leaves to the drive is here: the 402 state machine (:class:`~rehabkit.canopen.cia402.Drive402`)
moved by the controlword the master maps into an RPDO, and, on each SYNC while OPERATIONAL, the RPDOs taken in, the
joint driven (cyclic synchronous torque: the target torque in per mille of the rated torque 0x6076, applied only
while the power stage is on, clipped to the max torque 0x6072), and the TPDOs sent with the joint's state sampled at
the SYNC, in the drive's units. The PDO maps are the master's: written by SDO into the drive's dictionary and read
back from it as the node starts (or at the first SYNC after they change). The drive's live values (controlword,
targets, statusword, actual values) are served to SDO reads as they stand; its parameters are read once a master
writes them.

Its own limits: beyond the software position limits (0x607D) or the max speed (0x6080) it faults. A fault
(:meth:`SimulatedDrive.fault`) sends its EMCY; its reaction, like a quick stop, brings the joint to rest on the quick
stop deceleration (0x6085) with the drive's velocity loop (a gain tuned to its joint's inertia, as a drive's
auto-tuning sets it), then the torque goes off — at once where the quick stop option code (0x605A) is 0. A master's
heartbeat it is told to watch (0x1016) silent longer than its consumer time faults it too (0x8130), on the drive's
own clock: the SYNCs seen times the communication cycle period (0x1006). On a lock-step bus its own heartbeat
(0x1017) goes on that clock too, so every run decides the same way; in real time canopen's NMT slave sends it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import canopen

from rehabkit.canopen.cia402 import Drive402, State
from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.pdo_codec import PdoCodec

EDS = Path(__file__).resolve().parent / "eds" / "cia402_servo.eds"
SYNC_ID = 0x80
HEARTBEAT_LOST = 0x8130  # CiA 301/402 error code: life guard error or heartbeat error
OVERSPEED = 0x8400  # velocity speed controller
POSITION_LIMIT = 0x8612  # reference limit (beyond the software position limits)
DEFAULT_UNITS = DriveUnits()
STOP_BANDWIDTH = 40.0  # [rad/s] the drive's own loop in a quick stop or fault reaction (critically damped)
NMT_BYTE = {"INITIALISING": 0x00, "STOPPED": 0x04, "OPERATIONAL": 0x05, "PRE-OPERATIONAL": 0x7F}


class Joint(Protocol):
    """The joint a drive moves: ``apply`` a torque [N·m], ``read`` its position [rad], velocity [rad/s] and the torque
    it applies [N·m]."""

    def apply(self, torque: float) -> None: ...

    def read(self) -> tuple[float, float, float]: ...


# the parameters the drive acts on, read when a master writes them: (index, subindex)
PARAMETERS = ((0x1006, 0), (0x605A, 0), (0x6072, 0), (0x607D, 1), (0x607D, 2), (0x6080, 0), (0x6085, 0))
LIVE = ((0x6040, 0), (0x6071, 0), (0x6041, 0), (0x603F, 0), (0x6064, 0), (0x606C, 0), (0x6077, 0))


class SimulatedDrive:
    """Drive ``node_id`` on ``network`` moving ``joint`` (see the module's doc). ``inertia`` [kg·m² at the joint]:
    what its own loop (quick stops, fault reactions) is tuned to. ``own_sync``: it takes each SYNC itself
    (else whoever steps the plant calls :meth:`on_sync`, in order). ``clocked``: heartbeats on the SYNC clock."""

    def __init__(self, network: canopen.Network, node_id: int, joint: Joint, units: DriveUnits = DEFAULT_UNITS,
                 eds: Path = EDS, inertia: float = 0.01, own_sync: bool = True, clocked: bool = False):
        self.node = canopen.LocalNode(node_id, str(eds))
        network.add_node(self.node)
        self.joint, self.units, self.inertia, self.clocked = joint, units, inertia, clocked
        self.node.sdo[0x6076].raw = round(units.rated_torque_nm / units.gear_ratio * 1e3)  # the motor's [mN·m]
        self.par = {(i, s): self.node.sdo[i].raw if not s else self.node.sdo[i][s].raw for i, s in PARAMETERS}
        self.live = {k: 0 for k in LIVE}
        self.machine = Drive402(quick_stop_option=self.par[0x605A, 0])
        self._maps_changed = True
        self._rx: dict[int, tuple[PdoCodec, list]] = {}  # COB-ID → (its map, [the newest frame's data or None])
        self._tx: list[PdoCodec] = []
        if clocked:  # (canopen's NMT slave would start a wall-clock timer: this drive beats on its own clock)
            self.node.nmt.start_heartbeat = self._start_heartbeat
        self._beat_us, self._next_beat = 0, 0
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        if own_sync:
            network.subscribe(SYNC_ID, self.on_sync)
        network.subscribe(0x000, self._on_nmt)
        self.syncs = 0
        self._heard: dict[int, int] = {}  # a watched node → when its heartbeat came last [µs, the drive's clock]
        self._watch: dict[int, int] = {}  # a watched node → its consumer time [µs]
        self._network = network
        self._stop_v: float | None = None  # a stop under way: the speed its ramp started from [rad/s]
        self._stop_at, self._stop_q = 0, 0.0  # when it began; where its ramp's position is now [rad]
        self.emcy_sent: list[int] = []
        self.silent = self.heartless = False  # (injected faults: it answers nothing; its heartbeat stops)
        self._publish()

    @property
    def clock(self) -> int:
        """The drive's time [µs, exact]: SYNCs seen times the communication cycle period."""
        return self.syncs * self.par[0x1006, 0]

    def _start_heartbeat(self, ms: int) -> None:
        self._beat_us, self._next_beat = ms * 1000, self.clock

    def _on_read(self, index: int, subindex: int, od) -> int | None:
        return self.live.get((index, subindex))

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if (index, subindex) in self.par:
            self.par[index, subindex] = od.decode_raw(data)
            self.machine.quick_stop_option = self.par[0x605A, 0]
        elif (index, subindex) in self.live:
            self.live[index, subindex] = od.decode_raw(data)
        elif 0x1400 <= index <= 0x1BFF:  # the master (re)configures a PDO: its maps read again, once it is written
            self._maps_changed = True
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

    def _on_rpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._rx[can_id][1][0] = bytes(data)

    def _take_maps(self) -> None:
        self.node.rpdo.read(from_od=False)
        self.node.tpdo.read(from_od=False)
        for cob in self._rx:
            self._network.unsubscribe(cob, self._on_rpdo)
        self._rx = {}
        for pdo in self.node.rpdo.map.values():
            if pdo.enabled and pdo.map:
                codec = PdoCodec.of(pdo)
                self._rx[codec.cob_id] = (codec, [None])
                self._network.subscribe(codec.cob_id, self._on_rpdo)
        self._tx = [PdoCodec.of(p) for p in self.node.tpdo.map.values() if p.enabled and p.map]
        self._maps_changed = False

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0) -> None:
        """A SYNC: the drive samples its joint and sends its TPDOs, takes the RPDOs that came before it and drives the
        joint with them until the next."""
        if self.node.nmt.state != "OPERATIONAL" or self.silent:  # PDOs only in OPERATIONAL (CiA 301)
            return
        if self._maps_changed:  # (a map changed while OPERATIONAL: taken at the next cycle)
            self._take_maps()
        self.syncs += 1
        now = self.clock
        for node, limit in self._watch.items():
            if now - self._heard[node] > limit and self.machine.fault_code != HEARTBEAT_LOST:
                self.fault(HEARTBEAT_LOST)  # (the master's heartbeat silent: the drive stops on its own)
        if self._beat_us and now >= self._next_beat and not self.heartless:
            self._next_beat += self._beat_us
            self._network.send_message(0x700 + self.node.id, bytes([NMT_BYTE.get(self.node.nmt.state, 0x05)]))
        for codec, frame in self._rx.values():
            if frame[0] is not None:
                codec.unpack_into(frame[0], self.live)
        self._check_limits()
        before = self.machine.state
        self.machine.write(self.live[0x6040, 0])
        self._drive(before)
        self._publish()
        for codec in self._tx:
            self._network.send_message(codec.cob_id, codec.pack(self.live))

    def react(self) -> None:
        """A cycle of the drive's own without a SYNC (it lost it): its fault reaction or quick stop runs on."""
        self.syncs += 1
        before = self.machine.state
        self._drive(before)
        self._publish()

    def _check_limits(self) -> None:
        if not self.machine.torque_on or self.machine.state is State.FAULT_REACTION_ACTIVE:
            return
        q, qd, _ = self.joint.read()
        u, par = self.units, self.par
        pos, speed = u.direction * q * u.counts_per_rad, abs(qd) * u.counts_per_rad
        low, high = par[0x607D, 1], par[0x607D, 2]
        if low < high and not low <= pos <= high:
            self.fault(POSITION_LIMIT)
        elif par[0x6080, 0] and speed > par[0x6080, 0]:
            self.fault(OVERSPEED)

    def _drive(self, before: State) -> None:
        """The torque until the next SYNC: the target's while enabled; a stop's on its ramp; none otherwise."""
        m, u = self.machine, self.units
        stopping = m.state in (State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)
        max_nm = self.par[0x6072, 0] * 1e-3 * u.rated_torque_nm
        if stopping:
            q, qd, _ = self.joint.read()
            if m.state is not before or self._stop_v is None:  # the ramp starts from the state at the stop
                self._stop_v, self._stop_at, self._stop_q = qd, self.clock, q
            decel = self.par[0x6085, 0] / u.counts_per_rad
            ramp = max(0.0, abs(self._stop_v) - decel * (self.clock - self._stop_at) * 1e-6)
            if m.quick_stop_option == 0 or not decel or (ramp == 0.0 and abs(qd) < decel * self._period()):
                m.stopped()  # at rest (or no ramp asked for: the torque goes off at once)
            if m.torque_on:  # tracking the ramp (position and speed), then holding where it ended
                ref = ramp if self._stop_v >= 0 else -ramp
                self._stop_q += ref * self._period()
                w, inertia = STOP_BANDWIDTH, self.inertia
                tau = w * w * inertia * (self._stop_q - q) + 2 * w * inertia * (ref - qd)
                self.joint.apply(min(max_nm, max(-max_nm, tau)))
                return
        self._stop_v = None
        if m.state is State.OPERATION_ENABLED:
            target = self.live[0x6071, 0] * 1e-3 * u.rated_torque_nm * u.direction
            self.joint.apply(min(max_nm, max(-max_nm, target)))
        else:
            self.joint.apply(0.0)

    def _period(self) -> float:
        return max(self.par[0x1006, 0], 1) * 1e-6

    def _publish(self) -> None:
        """The drive's state: statusword, error code, actual position, velocity and torque (in its units)."""
        q, qd, tau = self.joint.read()
        u, live = self.units, self.live
        live[0x6041, 0] = self.machine.statusword
        live[0x603F, 0] = self.machine.fault_code
        live[0x6064, 0] = round(u.direction * q * u.counts_per_rad)
        live[0x606C, 0] = round(u.direction * qd * u.counts_per_rad)
        live[0x6077, 0] = max(-32768, min(32767, round(u.direction * tau / u.rated_torque_nm * 1e3)))

    def fault(self, code: int, register: int = 0x01) -> None:
        """The drive detects a fault (``code``: its CiA 402 error code): EMCY sent, the state machine's reaction."""
        if self.machine.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return
        self.machine.fault(code)
        self.emcy_sent.append(code)
        self.node.emcy.send(code, register)
        self._publish()
