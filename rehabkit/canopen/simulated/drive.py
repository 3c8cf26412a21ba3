"""A simulated CiA 402 servo drive on a CANopen network: what stands in for a joint's drive without the robot.

A :class:`~rehabkit.canopen.simulated.node.SimulatedNode` (a CiA 301 device) serving any drive's EDS or DCF — the
generic servo's by default — with the drive's own job: the 402 state machine (:class:`~rehabkit.canopen.cia402.
Drive402`) moved by the controlword however it comes (by SDO at once, in an RPDO at the next SYNC, or at once where
the RPDO is event-driven), and on each SYNC the joint driven and sampled. The modes of operation it runs: cyclic
synchronous torque (the target torque in per mille of the rated torque 0x6076, applied only while the power stage is
on, clipped to the max torque 0x6072), cyclic synchronous position or velocity (its own loop on the target, tuned to
the joint's inertia, plus the torque offset); in any other mode it supports it holds its position. 0x6061 follows
0x6060 at once; a mode the drive does not support (0x6502; where the EDS gives none: PP, PV, HM, CSP, CSV, CST) is
refused (SDO abort 0x06090030). The objects it acts on but its EDS lacks keep internal values, not served.

Its own limits: beyond the software position limits (0x607D) or the max speed (0x6080) it faults. A fault
(:meth:`SimulatedDrive.fault`) sends its EMCY (0x1001, 0x1003 kept); its reaction, like a quick stop, brings the joint
to rest on the quick stop deceleration (0x6085) — the drive's own loop tracks the ramp down to rest and holds there
(gains tuned to its joint's inertia, as a drive's auto-tuning sets them) —, then the torque goes off; at once where
the quick stop option code (0x605A) is 0. A fault reset clears its errors (EMCY 0x0000). A master's heartbeat it
watches falling silent (0x8130), or its SYNC (0x8100: the SYNC watchdog, armed while OPERATIONAL with the power stage
on), is met as its abort connection option code (0x6007) says: a fault, the torque off, or a quick stop — every time
it happens. Two objects only a simulation has are added to every drive's dictionary: 0x5FFE, the start position
[counts] its plant is reset to when 0x5FFF is written (1).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import canopen
from canopen.objectdictionary import INTEGER32, UNSIGNED8, ODVariable

from rehabkit.canopen.cia402 import Drive402, State
from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.simulated.device import INVALID_VALUE
from rehabkit.canopen.simulated.node import HEARTBEAT_LOST, SYNC_ID, SimulatedNode
from rehabkit.canopen.simulated.watchdogs import SyncWatchdog

EDS = Path(__file__).resolve().parents[1] / "eds" / "cia402_servo.eds"
SYNC_LOST = 0x8100  # CiA 301: communication error (here: the SYNC stopped coming)
OVERSPEED = 0x8400  # velocity speed controller
POSITION_LIMIT = 0x8612  # reference limit (beyond the software position limits)
DEFAULT_UNITS = DriveUnits()
STOP_BANDWIDTH = 40.0  # [rad/s] the drive's own loop in a quick stop or fault reaction (critically damped)
SERVO_BANDWIDTH = 40.0  # [rad/s] its position loop in CSP and CSV
# its integral action, as a servo's position loop has (a steady load held without offset: the arm's weight where no
# torque offset comes): Ki = INTEGRAL · w³ · J, well inside the PD's stability bound (Ki < 2 w³ J)
INTEGRAL = 0.25
START_POSITION, PLACE = 0x5FFE, 0x5FFF  # the simulation's own objects (a vendor may use any of 0x2000-0x5FFD)
SUPPORTED_MODES = 0x3A5  # PP, PV, HM, CSP, CSV, CST: where an EDS gives 0x6502 no value
CSP, CSV, CST = 8, 9, 10


class Joint(Protocol):
    """The joint a drive moves: ``apply`` a torque [N·m], ``read`` its position [rad], velocity [rad/s] and the torque
    it applies [N·m]."""

    def apply(self, torque: float) -> None: ...

    def read(self) -> tuple[float, float, float]: ...


# what the drive acts on and produces: (index, subindex) → its internal value where the EDS has none
KEYS = {(0x6007, 0): 1, (0x605A, 0): 2, (0x6060, 0): CST, (0x6061, 0): CST, (0x6072, 0): 1000, (0x607D, 1): 0,
        (0x607D, 2): 0, (0x6080, 0): 0, (0x6085, 0): 0, (0x6076, 0): 1000, (0x6502, 0): SUPPORTED_MODES,
        (0x6040, 0): 0, (0x6071, 0): 0, (0x607A, 0): 0, (0x60FF, 0): 0, (0x60B2, 0): 0, (0x6041, 0): 0,
        (0x603F, 0): 0, (0x6064, 0): 0, (0x606C, 0): 0, (0x6077, 0): 0, (START_POSITION, 0): 0, (PLACE, 0): 0}
CONTROLWORD, MODE, MODE_DISPLAY = (0x6040, 0), (0x6060, 0), (0x6061, 0)


def _simulation_objects() -> list[ODVariable]:
    start = ODVariable("Simulation start position", START_POSITION)
    start.data_type, start.access_type, start.default = INTEGER32, "rw", 0
    place = ODVariable("Simulation place", PLACE)
    place.data_type, place.access_type, place.min, place.max = UNSIGNED8, "wo", 1, 1
    return [start, place]


class SimulatedDrive(SimulatedNode):
    """Drive ``node_id`` on ``network`` serving ``eds`` (any drive's EDS or DCF) and moving ``joint`` (see the
    module's doc). ``inertia`` [kg·m² at the joint]: what its own loop (quick stops, fault reactions) is tuned to.
    ``own_sync``: it takes each SYNC itself (else whoever steps the plant calls :meth:`on_sync`, in order).
    ``clocked``: heartbeats on its own clock; ``now``: its watchdogs' clock [s]; ``cycle_us``: its cycle where neither
    its EDS nor its master sets one (0x1006, 0x60C2)."""

    watched = frozenset((CONTROLWORD, MODE))

    def __init__(self, network: canopen.Network, node_id: int, joint: Joint, units: DriveUnits = DEFAULT_UNITS,
                 eds: Path = EDS, inertia: float = 0.01, own_sync: bool = True, clocked: bool = False,
                 now: Callable[[], float] | None = None, cycle_us: int = 1000):
        super().__init__(network, node_id, eds, KEYS, KEYS, clocked, now, _simulation_objects(), cycle_us)
        self.joint, self.units, self.inertia = joint, units, inertia
        served = self.node.served
        served[0x6076, 0] = round(units.rated_torque_nm / units.gear_ratio * 1e3)  # the motor's [mN·m]
        if self.node.value(0x6502) is None:
            served[0x6502, 0] = SUPPORTED_MODES
        self.node.checks.append(self._check_mode)
        self.sync_watchdog = SyncWatchdog(self.now)
        self._init_values(0x6000, 0x9FFF)
        self._start()
        if own_sync:
            network.subscribe(SYNC_ID, self.on_sync)
        self.boot()

    def _start(self) -> None:
        """The application as it starts: the state machine in SWITCH ON DISABLED, the mode its EDS says."""
        v = self.values
        v[0x6076, 0] = self.node.served[0x6076, 0]
        v[MODE_DISPLAY] = v[MODE] if self.supports(v[MODE]) else 0
        self.machine = Drive402(quick_stop_option=v[0x605A, 0])
        self._cw_pending = False
        self._stop_v: float | None = None  # a stop under way: the speed its ramp started from [rad/s]
        self._stop_at, self._stop_q = 0, 0.0  # when it began; where its ramp's position is now [rad]
        self._follow: float | None = None  # CSP/CSV: the previous target position [rad]; else where it holds
        self._integral = 0.0  # [rad·s] its position loop's integral of the error, from where it was enabled
        self._cycle_state = self.machine.state  # (its state at the end of the last cycle)
        self._publish()

    def application_reset(self) -> None:
        self._start()

    def supports(self, mode: int) -> bool:
        """Whether it runs modes of operation ``mode`` (0x6502's bits; 0: no mode)."""
        return mode == 0 or (1 <= mode <= 10 and mode != 5 and bool(self.values[0x6502, 0] >> (mode - 1) & 1))

    def _check_mode(self, index: int, subindex: int, value: int) -> int | None:
        return INVALID_VALUE if (index, subindex) == MODE and not self.supports(value) else None

    def value_written(self, key: tuple[int, int]) -> None:
        if key == CONTROLWORD:  # (by SDO: at once, whatever the NMT state and whether SYNCs come)
            self._command(self.values[CONTROLWORD])
            self._publish()
            self.send_tpdos(at_sync=False)
        elif key == MODE:
            self.values[MODE_DISPLAY] = self.values[MODE]
        elif key == (0x605A, 0):
            self.machine.quick_stop_option = self.values[0x605A, 0]

    def pdo_written(self, key: tuple[int, int], at_sync: bool) -> None:
        if key == MODE:
            if self.supports(self.values[MODE]):
                self.values[MODE_DISPLAY] = self.values[MODE]
        elif at_sync:  # (the controlword: taken in the SYNC's cycle)
            self._cw_pending = True
        else:
            self.value_written(CONTROLWORD)

    def _command(self, controlword: int) -> None:
        was = self.machine.state
        self.machine.write(controlword)
        self._cw_pending = False
        if was is State.FAULT and self.machine.state is not State.FAULT:  # (a fault reset: its errors cleared)
            self.errors.reset()
            self.values[0x1001, 0] = self.errors.register

    def heartbeat_lost(self, node: int) -> None:
        self.connection_lost(HEARTBEAT_LOST)  # (the master's heartbeat silent: the drive stops on its own)

    def connection_lost(self, code: int) -> None:
        """Its master fell silent (heartbeat, SYNC): what its abort connection option code (0x6007) says — 1: fault;
        2: disable voltage (torque off); 3: quick stop (ramp down, then as 0x605A says); each with its EMCY."""
        if self.machine.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return
        option = self.values[0x6007, 0]
        if option in (2, 3):
            self.errors.raise_error(code, latched=False)
            self.values[0x1001, 0] = self.errors.register
            if option == 2:
                self.machine.disable_locally()
            else:
                self.machine.quick_stop_locally()
            self._publish()
        elif option:
            self.fault(code)

    def _sync_armed(self) -> bool:
        return self.nmt.state == "OPERATIONAL" and self.machine.torque_on and not self.silent

    def poll(self) -> None:
        """Its watchdogs on its clock: the heartbeat consumer, and the SYNC watchdog while armed."""
        super().poll()
        if self.sync_watchdog.expired(self.nmt.state == "OPERATIONAL" and self.machine.torque_on):
            self.connection_lost(SYNC_LOST)

    def on_sync(self, can_id: int = SYNC_ID, data: bytes = b"", timestamp: float = 0.0,
                at: float | None = None) -> None:
        """A SYNC (arrived ``at``, on its watchdogs' clock: else when its ``arrival`` says, else now): the drive
        samples its joint and sends its TPDOs, takes the RPDOs that came before it and drives the joint with them
        until the next."""
        if not self.begin_cycle():
            return
        if SYNC_LOST in self.errors.active:  # (the SYNC is back)
            self.errors.recover(SYNC_LOST)
        self._check_limits()
        if self._cw_pending:
            self._command(self.values[CONTROLWORD])
        self._cycle()
        if at is None and self.arrival is not None:
            at = self.arrival(timestamp)
        self.sync_watchdog.feed(self._sync_armed(), at)
        self.send_tpdos()

    def react(self) -> None:
        """A cycle of the drive's own without a SYNC (it lost it): its fault reaction or quick stop runs on."""
        self.tick()
        self._cycle()

    def _cycle(self) -> None:
        self._drive(self._cycle_state)
        self._cycle_state = self.machine.state
        self._publish()

    def _check_limits(self) -> None:
        if not self.machine.torque_on or self.machine.state is State.FAULT_REACTION_ACTIVE:
            return
        q, qd, _ = self.joint.read()
        u, par = self.units, self.values
        pos, speed = u.direction * q * u.position, abs(qd) * u.motor_speed
        low, high = par[0x607D, 1], par[0x607D, 2]
        if low < high and not low <= pos <= high:
            self.fault(POSITION_LIMIT)
        elif par[0x6080, 0] and speed > par[0x6080, 0]:
            self.fault(OVERSPEED)

    def _drive(self, before: State) -> None:
        """The torque until the next SYNC: the target's while enabled; a stop's on its ramp; none otherwise."""
        m, u = self.machine, self.units
        stopping = m.state in (State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)
        max_nm = self.values[0x6072, 0] * 1e-3 * u.rated_torque_nm
        if stopping:
            q, qd, _ = self.joint.read()
            if m.state is not before or self._stop_v is None:  # the ramp starts from the state at the stop
                self._stop_v, self._stop_at, self._stop_q = qd, self.clock, q
            decel = self.values[0x6085, 0] / u.acceleration
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
            self._follow, self._integral = None, 0.0

    def _target_torque(self) -> float:
        """The torque its mode asks for: CST the target torque; CSP and CSV the drive's own loop on the target
        position (with the velocity the targets move at) or velocity (with its integral), plus the torque offset; any
        other mode its loop holding where it was (its profile modes' targets are not simulated)."""
        u, live, mode = self.units, self.values, self.values[MODE_DISPLAY]
        per_mille = 1e-3 * u.rated_torque_nm * u.direction
        if mode == CST:
            return live[0x6071, 0] * per_mille
        q, qd, _ = self.joint.read()
        scale, dt = u.position * u.direction, self._period()
        if mode == CSP:
            q_t = live[0x607A, 0] / scale
            v_t = 0.0 if self._follow is None else (q_t - self._follow) / dt
        elif mode == CSV:  # (the velocity target's integral: where it leads, from where the drive was enabled)
            v_t = live[0x60FF, 0] / (u.velocity * u.direction)
            q_t = (q if self._follow is None else self._follow) + v_t * dt
        else:
            q_t, v_t = q if self._follow is None else self._follow, 0.0
        self._follow = q_t
        w, inertia = SERVO_BANDWIDTH, self.inertia
        self._integral += (q_t - q) * dt
        return live[0x60B2, 0] * per_mille + w * w * inertia * (q_t - q) + 2 * w * inertia * (v_t - qd) + \
            INTEGRAL * w**3 * inertia * self._integral

    def _period(self) -> float:
        return self.cycle_us * 1e-6

    def _publish(self) -> None:
        """The drive's state: statusword, error code, actual position, velocity and torque (in its units)."""
        q, qd, tau = self.joint.read()
        u, live = self.units, self.values
        live[0x6041, 0] = self.machine.statusword
        live[0x603F, 0] = self.machine.fault_code
        live[0x6064, 0] = round(u.direction * q * u.position)
        live[0x606C, 0] = round(u.direction * qd * u.velocity)
        live[0x6077, 0] = max(-32768, min(32767, round(u.direction * tau / u.rated_torque_nm * 1e3)))

    def fault(self, code: int) -> None:
        """The drive detects a fault (``code``: its CiA 402 error code): its EMCY (0x1001 and 0x1003 kept), the state
        machine's reaction."""
        if self.machine.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return
        self.machine.fault(code)
        self.send_emcy(code)
        self._publish()
