"""The canopen backend: the scenario's robot on CiA 402 servo drives on a CAN bus, the host as CANopen master.

At the first reset each drive is set up by SDO (the cycle, heartbeats both ways, cyclic synchronous torque, the run's
limits — position, speed, torque, quick stop deceleration and, from the e-stop's stop category, option code — the
PDO maps), started, and walked to OPERATION ENABLED. Each control step is one cycle: the safety layer's torques in the
RPDOs, SYNC, the TPDOs in. A drive's EMCY, a drive leaving OPERATION ENABLED, a lost heartbeat, missing TPDOs, a bus
that fails: each stops the run with its reason and code (:class:`~rehabkit.canopen.config.DriveFaultError`), the
other drives stopped by the safety layer in its category, the torque off when that stop ends. The e-stop latch is
this host's (the drives' master): no run starts while it is latched, and a drive's FAULT is reset only in the first
run after a person has cleared it (``rehabkit estop clear``).

With no ``bus`` named, simulated drives (:mod:`~rehabkit.canopen.simulated.rig`) on the robot's MuJoCo model start with
the run: in real time on a virtual bus of this process, or in lock-step (one cycle per SYNC, every frame delivered as
sent). The scene is mirrored on the host from the measured joints, as over the hardware link.
"""

from __future__ import annotations

import contextlib
import math
import time

import can
import numpy as np

from rehabkit.canopen.bus.bus_check import check_bus
from rehabkit.canopen.bus.can_bus import CanBus
from rehabkit.canopen.bus_health import METRICS, DriveNotes, bus_metrics, hold_interventions, latency_series
from rehabkit.canopen.config import CanopenConfig, DriveFaultError
from rehabkit.canopen.cycle_clock import CycleClock, own_gravity
from rehabkit.canopen.drives.ending import ENDED, bring_to_rest, release
from rehabkit.canopen.drives.limits import drive_limits
from rehabkit.canopen.drives.start_checks import check_no_fault, check_start_posture, unanswered
from rehabkit.canopen.drives.units import units_of
from rehabkit.canopen.injection import inject
from rehabkit.canopen.master import DriveMaster
from rehabkit.canopen.simulated.drive import EDS
from rehabkit.canopen.simulated.rig import DriveRig
from rehabkit.canopen.simulated.sensor import EDS as SENSOR_EDS
from rehabkit.core.kinds.backend import EStopLatchedError
from rehabkit.core.kinds.capabilities import FollowsReference, Instruments
from rehabkit.core.kinds.errors import SettingError
from rehabkit.core.kinds.interfaces import Backend, Context
from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.run.signals import signals_held
from rehabkit.core.safety.estop import RAMP_IN_AFTER_CLEAR_S, EStopLatch
from rehabkit.core.safety.event import SafetyEvent
from rehabkit.core.safety.stopping import joint_inertia
from rehabkit.hardware.bridge import HOLD_KD, HOLD_KP
from rehabkit.hardware.frame_server import FrameServer
from rehabkit.hardware.link.clock import wait_until
from rehabkit.hardware.mirrored_scene import MirroredScene, SceneMirror

START_CYCLES = 50  # SYNCs a reset sends at most until every node has answered one
HOLD_BANDWIDTH = 20.0  # [rad/s] this host's hold of the posture through a late step


class CanopenBackend(MirroredScene, Backend, Instruments, FollowsReference):
    """The robot's joints on CiA 402 drives over CANopen (see the module's doc)."""

    metrics = METRICS
    real_person = True
    latch_name = "{latch_prefix}{robot}{latch_suffix}"  # (this host's, the drives' master: sim-<robot> on simulated
    # drives, a rehearsal never latching the real robot; <robot>-<robot_id> on its own)

    def __init__(self, config: CanopenConfig, context: Context):
        specs, sensors, self.load = check_bus(config, context)
        robot = context.robot
        self.config, self.robot = config, robot
        self.timestep, self.period = self.timestep_for(config, context.control_dt), context.control_dt
        self.loop_delay = self.period  # (synchronous RPDOs: a cycle's torque acts from the next SYNC on)
        self.realtime = config.clock == "realtime"
        self.simulated = config.simulated
        self.n = robot.model.dof
        self.names = robot.model.joint_names
        effort = robot.model.limits.effort
        self.latch = EStopLatch.named(self.latch_name.format(robot=robot.model.name, **config.model_dump()))
        self.safety_config = context.safety
        self.mirror = SceneMirror(robot.model, context.world)
        self.frames = FrameServer(self.mirror.model) if context.world is not None and context.world.cameras else None
        self.measured = np.zeros(self.mirror.measured_count)
        self.q, self.qd, self.tau = np.zeros(self.n), np.zeros(self.n), np.zeros(self.n)
        self._posed = False
        self.cycles = 0
        self.latency: list[float] = []
        self.t0 = self.deadline = 0.0
        self._configured = self._started = False
        self._fault: DriveFaultError | None = None
        self.clock: CycleClock | None = None  # (real time, from the reset)
        self._note = context.note or (lambda t, text: None)
        self._hold_kp, self._hold_kd = HOLD_KP, HOLD_KD  # (the bridge's, for a robot without a dynamic model)
        self._following = np.array([s.mode != "cst" for s in specs])
        self.follows = bool(self._following.any())  # (CSP/CSV drives: the loop hands over the targets)
        self._targets: tuple[np.ndarray, np.ndarray] | None = None
        self._injections = sorted(config.inject, key=lambda f: f.at_s)
        trace = None
        if config.trace != "none" and context.out_dir is not None:
            trace = context.out_dir / f"can.{config.trace}"
        bus = config.bus
        try:
            self.bus = CanBus(bus.interface if bus else None, bus.channel if bus else None, config.bitrate,
                              simulated=config.bus is None, lockstep=not self.realtime, trace=trace, clock=self._now,
                              master_id=config.master_node_id)
        except (OSError, can.CanError, ImportError, ValueError) as exc:  # (python-can's own words: no such device)
            if bus is None:
                raise
            raise SettingError("bus", f"python-can cannot open {bus.interface} {bus.channel}: {exc} (is the "
                               "adapter plugged in, its driver loaded, the interface up?)") from None
        try:
            eds = [str(context.resolve(s.eds)) if s.eds else str(EDS) for s in specs]
            self.units = [units_of(s, effort[i], eds[i]) for i, s in enumerate(specs)]
            self.rig = None
            if config.bus is None:  # simulated drives of this run's own
                from rehabkit.hardware.plant import MujocoPlant  # (only a run with simulated drives loads MuJoCo here)

                plant = MujocoPlant(robot, config.timestep, context.instruments,
                                    context.world.loads if context.world else (), context.seed or 0)
                self.rig = DriveRig(self.bus.drives, plant, [s.node_id for s in specs], self.units,
                                    clocked=not self.realtime, eds=eds, sensors=[s.node_id for s in sensors])
                if self.realtime:  # (their own watchdog on the wall clock: a SYNC that stops coming faults them)
                    self.rig.watch_sync(config.sync_timeout_ms * 1e-3)
            nodes = [(s.node_id, path) for s, path in zip(specs, eds, strict=True)]
            instruments = [(s.node_id, str(context.resolve(s.eds)) if s.eds else str(SENSOR_EDS), i.name)
                           for s, i in zip(sensors, context.instruments, strict=True)]
            self.master = DriveMaster(self.bus.network, nodes, self.units, self.names, config, self._now,
                                      [s.rated_torque_nm is None for s in specs], instruments, [s.mode for s in specs],
                                      [s.enable for s in specs])
            self._instrument = {i.name: k for k, i in enumerate(context.instruments)}
            self.notes = DriveNotes(context.note, self.master)
        except BaseException:
            self.bus.close(keep_trace=False)
            raise

    @classmethod
    def timestep_for(cls, config: CanopenConfig, control_dt: float) -> float:
        """The simulated drives' plant step; on a robot's own bus, the cycle (no plant steps there)."""
        return control_dt if config.bus is not None and not config.bus.simulated else config.timestep

    @classmethod
    def check(cls, config: CanopenConfig, context: Context) -> list[str]:
        """``validate``: the drives against the robot, their EDS files, the bus load at the control rate; a load
        that fits but leaves little room said."""
        _, _, load = check_bus(config, context)
        return [crowded] if (crowded := load.crowded()) else []

    def _now(self) -> float:
        return time.monotonic() - self.t0 if self.realtime else self.master.cycles * self.period if \
            hasattr(self, "master") else 0.0

    # -- Backend -----------------------------------------------------------------------------------------------

    def reset(self, q0: np.ndarray) -> None:
        if self.frames is not None:
            self.frames.wait_ready()
        where = f"the drives on {self.provenance()['bus']}"
        if self.latch.latched() is not None:
            raise EStopLatchedError(self.latch.refusal(where), self.latch.name, where)
        cleared = self.latch.take_ramp_in()
        self.ramp_in_after_clear = RAMP_IN_AFTER_CLEAR_S if cleared else 0.0
        q0 = np.asarray(q0, float)
        self.t0 = time.monotonic()
        if not self._configured:
            self._limits = drive_limits(self.robot.model, self.safety_config, q0)
            for text in self.master.configure(self.period, self._limits):
                self._note(0.0, text)  # (a limit more than its object holds: told the largest it holds)
            self._configured = True
        if self.simulated:  # (placed before the drives are enabled, within their limits, and again once they are:
            self.master.place(q0)  # with the power stages off the arm sagged meanwhile)
        self.deadline = time.monotonic()
        for _ in range(START_CYCLES):  # the drives' states and the joints, the power stages still off (the first
            self._paced(np.zeros(self.n))  # cycles after NMT start may find a drive still taking its maps)
            if not math.isnan(self.latency[-1]):
                break
        else:
            raise unanswered(self.master, self.names, START_CYCLES)
        check_no_fault(self.master, self.names, cleared, self.latch.name)
        check_start_posture(self.master, self.names, q0, self.simulated)
        self.q, self.qd = q0.copy(), np.zeros(self.n)
        self._q0, self._cleared = q0, cleared
        self._started, self._fault = False, None
        inertia = joint_inertia(self.robot.model, q0)
        if inertia is not None:
            self._hold_kp, self._hold_kd = HOLD_BANDWIDTH**2 * inertia, 2 * HOLD_BANDWIDTH * inertia

    def _enable(self) -> None:
        """At the loop's first step (no gap in the SYNC before the loop takes over): the 402 walk to OPERATION ENABLED,
        the simulated plant placed at the start again, held one cycle by gravity; in real time, the bus's clock."""
        q0 = self._q0
        if self.realtime:  # the process keeps the cycles' deadlines from before the walk (its power stages on)
            self._gravity = own_gravity(self.robot)
            self.clock = CycleClock(self.period, self._cycle, self._hold_torque, lambda: self.master.q)
            self.clock.keep_deadlines()
        for text in self.master.watch_host():
            self._note(0.0, text)
        self.deadline = time.monotonic()
        self.master.enable(self._paced, fault_reset=self._cleared)
        if self.simulated:
            self.master.place(q0)
        self._paced(self.robot.gravity_torque(q0))
        self.notes.restart()
        if self.clock is not None:  # enabled drives expect their SYNC every cycle: from now on, whatever the loop does
            self.clock.start(self.tau)

    def _hold_torque(self, posture: np.ndarray) -> np.ndarray:
        """Holding ``posture`` as the bridge holds (PD with gravity compensation) from the newest state, critically
        damped at HOLD_BANDWIDTH on each joint's inertia (the bus's cycle of delay would make a light wrist ring at the
        bridge's gains); in the clock's thread, its gravity from a dynamic model's workspace of its own."""
        m = self.master
        return self._hold_kp * (posture - m.q) - self._hold_kd * m.qd + self._gravity(m.q)

    def _cycle(self, tau: np.ndarray) -> None:
        targets = self._targets or (None, None)
        latency = self.master.cycle(tau, 0.8 * self.period if self.realtime else 0.0, *targets)
        self.latency.append(latency)

    def follow(self, q: np.ndarray, qd: np.ndarray) -> None:
        """CSP/CSV drives' targets for the next cycle (the reference as the safety layer lets it through); their
        torque offset is the gravity compensation there, the controller's torque not sent."""
        self._targets = (np.array(q, float), np.array(qd, float))

    def _paced(self, tau: np.ndarray) -> None:
        """One cycle of the set-up, on the bus's clock (real time: at its deadline)."""
        if self.realtime:
            wait_until(self.deadline)
            self.deadline += self.period
        self._cycle(tau)

    def state(self) -> tuple[float, np.ndarray, np.ndarray]:
        return self.cycles * self.period, self.q, self.qd

    def command(self, tau: np.ndarray) -> None:
        self.tau = np.array(tau, float)
        if self._targets is not None:  # (CSP/CSV drives: gravity compensation at the target, as the torque offset)
            self.tau[self._following] = self.robot.gravity_torque(self._targets[0])[self._following]

    def step(self, n: int = 1) -> None:
        """One cycle (``n`` plant steps of the simulated drives: the control period)."""
        if not self._started:
            self._started = True
            tau, self.tau = self.tau, self.robot.gravity_torque(self._q0)
            self._enable()
            self.tau = tau
        if self._injections and self.cycles * self.period >= self._injections[0].at_s - 1e-9:
            inject(self, self._injections.pop(0))
        if self.clock is not None:
            self.clock.step(self.tau)
        else:
            self._cycle(self.tau)
        self.cycles += 1
        self.q, self.qd, self._posed = self.master.q.copy(), self.master.qd.copy(), False
        fault = self.master.fault()
        self.notes.say(self.cycles * self.period, self.realtime)
        if fault is not None and self._fault is None:
            self._fault = fault  # latched as an e-stop: the drives' fault is reset only after a person clears it
            self.latch.press(str(fault), by=f"drive {fault.node}" if fault.node is not None else "the CAN bus")
            if self.safety_config is not None and self.safety_config.category_of("backend") == 0:
                self.master.torque_off()
            raise fault

    def engage_brakes(self) -> bool:
        """The safety layer's torque has gone off: the drives' power stages too (disable voltage); the robot's brakes
        where it has them."""
        self.master.torque_off()
        return self.rig.plant.brake() if self.rig is not None else self.robot.model.brakes is not None

    def latch_estop(self, reason: str) -> bool:
        """Latch the e-stop here, at the drives' master: no run starts until a person clears it."""
        self.latch.press(reason, by="rehabkit (canopen master)")
        return True

    def latched_estop(self) -> str | None:  # (the drives' master's latch)
        return self.latch.name if self.latch.latched() is not None else None

    def read_instrument(self, name: str) -> np.ndarray:
        """An instrument's newest reading, from its sensor's TPDO (sampled at the cycle's SYNC)."""
        return self.master.readings[self._instrument[name]].copy()

    def interventions(self) -> list[SafetyEvent]:
        """The cycles this host held the posture through, because the loop's step was late."""
        return hold_interventions(self)

    def provenance(self) -> dict[str, str]:
        bus = self.config.bus
        return {"bus": f"{bus.interface}:{bus.channel}" if bus else "simulated CiA 402 drives (virtual CAN bus)",
                "drives": ", ".join(str(r.id) for r in self.master.remotes)}

    def run_metrics(self, trace) -> dict[str, float]:
        return bus_metrics(self)

    def outputs(self) -> dict[str, str]:
        """Its CAN trace (renamed into place when the bus closes)."""
        return {"can_trace": self.bus.trace.name} if self.bus.trace is not None else {}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return latency_series(self)

    def close(self) -> None:
        """The run's end, however it came (:mod:`~rehabkit.canopen.drives.ending`): the robot brought to rest in the
        run's stop category, the power stages off, the drives' watchdogs of the host disarmed, NMT pre-operational;
        then the bus closed. SIGINT and SIGTERM are held off meanwhile: a second Ctrl-C, a service manager's SIGTERM,
        must not leave the drives powered and operational."""
        with signals_held():
            try:
                if self.clock is not None:  # (its own cycles end; the end's keep their deadlines, then the process is
                    self.clock.stop()  # put back as it was)
                try:
                    if self._configured:
                        self._end()
                finally:
                    if self.clock is not None:
                        self.clock.close()
                if self.rig is not None:
                    self.rig.stop_watching()
                self.bus.close(keep_trace=self._started)  # (a run refused at its reset leaves no trace file)
            finally:
                if self.frames is not None:
                    self.frames.close()

    def _end(self) -> None:
        limits = self._limits
        self.deadline = time.monotonic()
        with contextlib.suppress(*ENDED):  # (a bus already down: nothing more reaches the drives)
            bring_to_rest(self.master, self._paced, limits.stop_category, limits.decel, self.period)
        release(self.master, "STOPPED" if self.config.end_nmt == "stopped" else "PRE-OPERATIONAL")


@hookimpl
def rehabkit_register_backends(registry) -> None:
    registry.add("canopen", config=CanopenConfig, factory=CanopenBackend)
