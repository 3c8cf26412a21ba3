"""A simulated CiA 402 servo drive on a CANopen network: what stands in for a joint's drive without the robot.

A :class:`~rehabkit.canopen.simulated.node.SimulatedNode` serving the generic servo's EDS, with the drive's own job: the
402 state machine (:class:`~rehabkit.canopen.cia402.Drive402`) moved by the controlword the master maps into an RPDO,
and, on each SYNC while OPERATIONAL, the joint driven (cyclic synchronous torque: the target torque in per mille of
the rated torque 0x6076, applied only while the power stage is on, clipped to the max torque 0x6072; or cyclic
synchronous position or velocity: its own loop on the target, tuned to the joint's inertia, plus the torque offset),
and the TPDOs sent with the joint's state sampled at the SYNC, in the drive's units.

Its own limits: beyond the software position limits (0x607D) or the max speed (0x6080) it faults. A fault
(:meth:`SimulatedDrive.fault`) sends its EMCY; its reaction, like a quick stop, brings the joint to rest on the quick
stop deceleration (0x6085) — the drive's own loop tracks the ramp down to rest and holds there (gains tuned to its
joint's inertia, as a drive's auto-tuning sets them) —, then the torque goes off; at once where the quick stop option
code (0x605A) is 0. A master's heartbeat it watches falling silent (0x8130), or its SYNC, is met as its abort
connection option code (0x6007) says: a fault, the torque off, or a quick stop.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import canopen

from rehabkit.canopen.cia402 import Drive402, State
from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.simulated.node import SYNC_ID, SimulatedNode

EDS = Path(__file__).resolve().parents[1] / "eds" / "cia402_servo.eds"
HEARTBEAT_LOST = 0x8130  # CiA 301/402 error code: life guard error or heartbeat error
OVERSPEED = 0x8400  # velocity speed controller
POSITION_LIMIT = 0x8612  # reference limit (beyond the software position limits)
DEFAULT_UNITS = DriveUnits()
STOP_BANDWIDTH = 40.0  # [rad/s] the drive's own loop in a quick stop or fault reaction (critically damped)
SERVO_BANDWIDTH = 40.0  # [rad/s] its position loop in CSP and CSV


class Joint(Protocol):
    """The joint a drive moves: ``apply`` a torque [N·m], ``read`` its position [rad], velocity [rad/s] and the torque
    it applies [N·m]."""

    def apply(self, torque: float) -> None: ...

    def read(self) -> tuple[float, float, float]: ...


# the parameters the drive acts on, read when a master writes them, and its process data: (index, subindex)
PARAMETERS = ((0x6007, 0), (0x605A, 0), (0x6060, 0), (0x6072, 0), (0x607D, 1), (0x607D, 2), (0x6080, 0), (0x6085, 0))
LIVE = ((0x6040, 0), (0x6071, 0), (0x607A, 0), (0x60FF, 0), (0x60B2, 0), (0x6041, 0), (0x603F, 0), (0x6064, 0),
        (0x606C, 0), (0x6077, 0))


class SimulatedDrive(SimulatedNode):
    """Drive ``node_id`` on ``network`` moving ``joint`` (see the module's doc). ``inertia`` [kg·m² at the joint]:
    what its own loop (quick stops, fault reactions) is tuned to. ``own_sync``: it takes each SYNC itself
    (else whoever steps the plant calls :meth:`on_sync`, in order). ``clocked``: heartbeats on the SYNC clock."""

    def __init__(self, network: canopen.Network, node_id: int, joint: Joint, units: DriveUnits = DEFAULT_UNITS,
                 eds: Path = EDS, inertia: float = 0.01, own_sync: bool = True, clocked: bool = False):
        super().__init__(network, node_id, eds, PARAMETERS, LIVE, clocked)
        self.joint, self.units, self.inertia = joint, units, inertia
        self.node.sdo[0x6076].raw = round(units.rated_torque_nm / units.gear_ratio * 1e3)  # the motor's [mN·m]
        self.machine = Drive402(quick_stop_option=self.par[0x605A, 0])
        if own_sync:
            network.subscribe(SYNC_ID, self.on_sync)
        self._stop_v: float | None = None  # a stop under way: the speed its ramp started from [rad/s]
        self._stop_at, self._stop_q = 0, 0.0  # when it began; where its ramp's position is now [rad]
        self._follow: float | None = None  # CSP/CSV: the previous target position [rad]
        self._publish()

    def parameter_written(self, index: int, subindex: int) -> None:
        self.machine.quick_stop_option = self.par[0x605A, 0]

    def heartbeat_lost(self, node: int) -> None:
        self.connection_lost(HEARTBEAT_LOST)  # (the master's heartbeat silent: the drive stops on its own)

    def connection_lost(self, code: int) -> None:
        """Its master fell silent (heartbeat, SYNC): its EMCY, then what its abort connection option code (0x6007)
        says — 1: fault; 2: disable voltage (torque off); 3: quick stop (ramp down, then as 0x605A says)."""
        if code in self.emcy_sent or self.machine.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return
        option = self.par[0x6007, 0]
        if option == 2:
            self.send_emcy(code)
            self.machine.disable_locally()
        elif option == 3:
            self.send_emcy(code)
            self.machine.quick_stop_locally()
        elif option:
            self.fault(code)

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0) -> None:
        """A SYNC: the drive samples its joint and sends its TPDOs, takes the RPDOs that came before it and drives the
        joint with them until the next."""
        if not self.begin_cycle():
            return
        self._check_limits()
        before = self.machine.state
        self.machine.write(self.live[0x6040, 0])
        self._drive(before)
        self._publish()
        self.send_tpdos()

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
            target = self._target_torque()
            self.joint.apply(min(max_nm, max(-max_nm, target)))
        else:
            self.joint.apply(0.0)
            self._follow = None

    def _target_torque(self) -> float:
        """The torque its mode asks for: CST the target torque; CSP and CSV the drive's own loop on the target
        position (with the velocity the targets move at) or velocity (with its integral), plus the torque offset."""
        u, live, mode = self.units, self.live, self.par[0x6060, 0]
        per_mille = 1e-3 * u.rated_torque_nm * u.direction
        if mode not in (8, 9):
            return live[0x6071, 0] * per_mille
        q, qd, _ = self.joint.read()
        scale, dt = u.counts_per_rad * u.direction, self._period()
        if mode == 8:
            q_t = live[0x607A, 0] / scale
            v_t = 0.0 if self._follow is None else (q_t - self._follow) / dt
            self._follow = q_t
        else:  # (the velocity target's integral: where it leads, from where the drive was enabled)
            v_t = live[0x60FF, 0] / scale
            q_t = (q if self._follow is None else self._follow) + v_t * dt
            self._follow = q_t
        w, inertia = SERVO_BANDWIDTH, self.inertia
        return live[0x60B2, 0] * per_mille + w * w * inertia * (q_t - q) + 2 * w * inertia * (v_t - qd)

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
        self.send_emcy(code, register)
        self._publish()
