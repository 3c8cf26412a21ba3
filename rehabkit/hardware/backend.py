"""Hardware backend: the scenario's robot over the UDP link to a robot-side bridge, in soft real time.

Each control tick the newest torque command goes out (after the safety layer), the loop sleeps to its deadline, and
the newest valid state that came back is taken. Deadline misses (a tick that starts late), tick lateness (jitter)
and round-trip latency (from the echo of each command in the bridge's state) are counted for ``summary.json``, and
so are the bridge's holds through gaps in the commands (``bridge_stale_ms``; see the bridge), each a ``stale-
command`` safety intervention. A stall of this host longer than that hold pauses the task's timeline (the missed
ticks are skipped and counted, ``ticks_skipped_s``) rather than catching up: the bridge has held the robot
meanwhile, and a burst of late commands would drive it toward a reference that ran ahead. No valid state for
``state_timeout_s``: the link is lost, the run stops with that reason (:class:`LinkLostError`), the logs complete.
With ``spawn_bridge`` the backend starts ``rehabkit bridge`` itself, driving the robot's MuJoCo model as the plant:
the same scenario runs against the link with only ``backend:`` changed.

The scene is mirrored on the host from the measured joints (:class:`~rehabkit.hardware.mirrored_scene.SceneMirror`):
the log draws the whole robot, the scripted objects live there, a simulated camera looks at it from a sensor thread
(its pixels rendered in a process of their own: :mod:`~rehabkit.hardware.frame_server`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from rehabkit.core.kinds.backend import EStopLatchedError
from rehabkit.core.kinds.capabilities import CompliantGaps, Instruments
from rehabkit.core.kinds.interfaces import Backend, Context
from rehabkit.core.kinds.sensor import INSTRUMENT_DIM
from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.run.signals import signals_held
from rehabkit.core.safety.estop import RAMP_IN_AFTER_CLEAR_S
from rehabkit.core.safety.event import SafetyEvent
from rehabkit.hardware.bridge_process import spawn_bridge, stop_bridge
from rehabkit.hardware.bridge_says import clear_right, hold_breach, hold_reason, latched_message
from rehabkit.hardware.config import (
    BridgeHoldError,
    HardwareConfig,
    LinkKeyError,
    LinkLostError,
    SessionTakenOverError,
)
from rehabkit.hardware.frame_server import FrameServer
from rehabkit.hardware.link.clock import wait_until
from rehabkit.hardware.link.host_end import LOCKSTEP_REPLY_S, HostLink
from rehabkit.hardware.link.protocol import (
    CMD_BRAKE,
    CMD_COMPLIANT,
    CMD_ESTOP,
    CMD_LATCH,
    CMD_RESET,
    COMMAND,
    ESTOPPED,
    HOLDING,
    PLAIN,
    RAMP_IN,
    STATE,
    TICK,
    Receiver,
)
from rehabkit.hardware.link_stats import METRICS, link_metrics, link_series, note_stale, stale_interventions
from rehabkit.hardware.mirrored_scene import MirroredScene, SceneMirror


class HardwareBackend(MirroredScene, Backend, Instruments, CompliantGaps):
    """The robot over UDP (a bridge in front of its drives, or of a MuJoCo plant); the scene mirrored on the host
    from the measured joints (drawn, scripted objects, cameras rendered in a process of their own)."""

    metrics = METRICS
    real_person = True
    latch_name = "{robot}-{robot_id}"  # (a bridge this run starts reads it here)

    def __init__(self, config: HardwareConfig, context: Context):
        config = config.under(context.safety)  # the envelope's link timing over the backend's defaults
        self.config, self.timestep = config, config.timestep
        self.realtime = config.clock == "realtime"  # else the link's clock is the count of ticks (HostLink.clock)
        robot = context.robot
        self.n = robot.model.dof
        self.estop_name = self.latch_name.format(robot=robot.model.name, robot_id=config.robot_id)  # (at the bridge)
        self.key = config.key(context)
        self._note = context.note
        self.brakes = robot.model.brakes is not None
        self._flags = 0  # sent with every command (the brakes, once applied)
        self.limits, self.joint_names = robot.model.limits, robot.model.joint_names
        self.revolute = robot.model.revolute
        self.mirror = SceneMirror(robot.model, context.world)
        # (on the lock-step clock the loop waits for each frame: rendered at normal priority, not idle)
        self.frames = FrameServer(self.mirror.model, idle=self.realtime) \
            if context.world is not None and context.world.cameras else None
        self.measured = np.zeros(self.mirror.measured_count)
        # the instruments' readings each state carries (3 values each, in the run's order), read by name
        self._instrument_at = {i.name: slice(INSTRUMENT_DIM * k, INSTRUMENT_DIM * (k + 1))
                               for k, i in enumerate(context.instruments)}
        self.instruments = np.zeros(INSTRUMENT_DIM * len(context.instruments))
        self._posed = False
        self.process = None
        port = config.port
        if config.spawn_bridge:
            self.process, port = spawn_bridge(context, config)
        self.rx = Receiver(STATE, config.robot_id, self.n, measured=len(self.measured),
                           instruments=len(self.instruments), max_age=config.max_age_s)
        self.wire = HostLink(config.host, port, config.robot_id, self.key, self.rx, config.timestep,
                             config.rekey_s)
        self.addr, self.tau = self.wire.addr, np.zeros(self.n)
        self.q, self.qd = np.zeros(self.n), np.zeros(self.n)
        self.applied = np.zeros(self.n)
        self.status = 0
        self.t0 = self.deadline = self.last_state = 0.0
        self.misses, self.ticks = 0, 0
        self.lateness: list[float] = []
        self.rtt: list[float] = []
        self.rtt_at: list[int] = []  # round trips measured before each tick, to place them on the timeline
        self.held_at: float | None = None  # when the bridge first reported holding the robot
        self.stale_holds: list[list[float]] = []  # [start, ticks] of each gap in the commands the bridge held through
        self._held, self._stale_open, self._state_t = 0, False, 0.0
        self.silent_ticks, self._got = 0, False
        self.resync_s, self.skipped_s = config.bridge_stale_ms / 1e3, 0.0
        self._started = False
        self._estop_sent = False
        self._fault: BridgeHoldError | None = None

    @classmethod
    def check(cls, config: HardwareConfig, context: Context) -> None:
        """``validate``: the key file (there, owner-only, this robot's)."""
        config.key(context)

    # -- link ------------------------------------------------------------------

    def _now(self) -> float:
        return time.monotonic() if self.realtime else self.wire.clock * self.timestep

    def _send(self, values: np.ndarray, flags: int = 0, tick: bool = False) -> float:
        """A command; with ``tick`` (lock-step) it also tells the bridge to tick at the link's time (the clock
        rides on it: see :mod:`rehabkit.hardware.link.protocol`)."""
        sent = self._now()
        self.wire.send(COMMAND, values, sent, flags | (TICK if tick else 0))
        return sent

    def _tick_lockstep(self, timeout: float = LOCKSTEP_REPLY_S, sent: bool = False) -> bool:
        return self.wire.tick_lockstep(self._receive, timeout, sent)

    def _receive(self) -> None:
        for plain, now in self.wire.arrived(self._now, not self.realtime):
            msg = self.rx.take(plain, now)
            if msg is None:
                continue
            self.q, self.qd = msg.values[0].copy(), msg.values[1].copy()  # new arrays: other threads may hold the old
            self.applied = msg.values[2].copy()  # the torque the robot side applied (after its own clipping)
            self.measured, self.instruments, self._posed = msg.measured, msg.instruments, False
            self.status, self.last_state, self._got = msg.status, now, True
            if self._started:
                note_stale(self, msg, now - self.t0)
            if self._started and msg.status & HOLDING and self.held_at is None:
                self.held_at = now - self.t0
                if not self._estop_sent:  # the bridge stopped the robot on its own: the run must know why
                    self._fault = BridgeHoldError(f"the bridge holds the robot ({hold_reason(self, msg.status)}) "
                                                  f"at t={self.held_at:.3f}s", hold_breach(self, msg.status),
                                                  status=msg.status, at_s=self.held_at)
            if msg.echo > 0:
                self.rtt.append(now - msg.echo)

    def read_instrument(self, name: str) -> np.ndarray:
        """An instrument's reading in the newest state (read by the robot side at the tick that state closes)."""
        return self.instruments[self._instrument_at[name]].copy()

    def interventions(self) -> list[SafetyEvent]:
        """The bridge's holds through gaps in the commands, as safety events."""
        return stale_interventions(self)

    # -- Backend ----------------------------------------------------------------

    def reset(self, q0: np.ndarray) -> None:
        if self.frames is not None:
            self.frames.wait_ready()  # started with the backend; up before the loop
        if self.key is not None and self.wire.link is PLAIN:
            self.wire.open_session()
            if self._note is not None:
                self._note(0.0, f"link: authenticated session {self.wire.link.id:08x} with the bridge at "
                                f"{self.wire.where}, key {self.key.id}")
        self.wire.refused = None
        limit = time.monotonic() + 5.0
        while time.monotonic() < limit:  # the bridge may still be starting: ask until it answers from q0
            self._send(np.asarray(q0, float), CMD_RESET, tick=not self.realtime)
            self._got = False
            if self.realtime:
                time.sleep(0.005)
                self._receive()
            else:
                self._tick_lockstep(0.2, sent=True)
            if self.wire.refused is not None:
                raise LinkKeyError(self.wire.where, None, self.wire.refused, "key-needed")  # (a keyless host's)
            self._taken_over()
            if self._got and self.status & ESTOPPED:  # latched at the robot: no session starts
                raise EStopLatchedError(latched_message(self), self.estop_name,
                                        f"the robot behind the bridge at udp://{self.addr[0]}:{self.addr[1]}",
                                        None if self.process is not None else clear_right(self.status))
            if self._got and np.abs(self.q - q0).max() < 1e-3:  # one plant step after the reset
                break
        else:
            raise LinkLostError(f"the bridge at udp://{self.addr[0]}:{self.addr[1]} does not answer a reset"
                                + (" (is `rehabkit bridge` running there, for this robot and robot_id?)"
                                   if self.realtime else " (was it started with --lockstep?)"))
        self.t0 = self.deadline = self.last_state = self._now()
        self.ramp_in_after_clear = RAMP_IN_AFTER_CLEAR_S if self.status & RAMP_IN else 0.0
        self._started = False
        self.held_at, self._fault, self._estop_sent = None, None, False  # a reset re-enables the bridge
        self._flags = 0
        self.stale_holds, self._held, self._stale_open, self._state_t = [], 0, False, 0.0

    def state(self) -> tuple[float, np.ndarray, np.ndarray]:
        return self.deadline - self.t0, self.q, self.qd

    def command(self, tau: np.ndarray) -> None:
        self.tau = np.array(tau, float)

    def comply(self, on: bool) -> None:
        """Tell the bridge (with every command from now on) that the torques yield: its hold through a gap in the
        commands is then damping and gravity compensation only."""
        self._flags = self._flags | CMD_COMPLIANT if on else self._flags & ~CMD_COMPLIANT

    def engage_brakes(self) -> bool:
        """Tell the bridge to apply the robot's brakes (with every command from now on)."""
        self._flags |= CMD_BRAKE
        return self.brakes

    def step(self, n: int = 1) -> None:
        if not self._started:  # the timeline starts with the loop, not at the reset (setup work comes between)
            self._started = True
            self.deadline = self.last_state = self.t0 = self._now()
        cut = self.config.cut_commands_at_s
        for _ in range(n):
            sent = cut is None or self._now() - self.t0 < cut  # (a fault a safety-skill test injects: a cut link)
            if sent:
                self._send(self.tau, self._flags, tick=not self.realtime)
            self.deadline += self.timestep
            self._got = False
            late = self._pace(sent)
            self.ticks += 1
            self.lateness.append(late)
            if late > self.resync_s:
                # a stall longer than the bridge's hold: it has held the robot, so rushing through the missed ticks
                # would drive it with a reference that ran ahead meanwhile; the task's timeline pauses instead
                skipped = math.floor(late / self.timestep) * self.timestep
                self.deadline += skipped
                self.t0 += skipped
                self.skipped_s += skipped
            self.rtt_at.append(len(self.rtt))
            if late > self.timestep:  # this tick starts after the next one was due
                self.misses += 1
            # silence counted in our own ticks too: after a stall of this host, states still in flight get a chance
            if self.realtime:  # (lock-step: all that came before the bridge's answer is in)
                self._receive()
            self.silent_ticks = 0 if self._got else self.silent_ticks + 1
            self._taken_over()
            if self._fault is not None:
                fault, self._fault = self._fault, None
                raise fault
            silent = self._now() - self.last_state
            if silent > self.config.state_timeout_s and self.silent_ticks * self.timestep > self.config.state_timeout_s:
                raise LinkLostError(f"no valid state from the bridge for {1e3 * silent:.0f} ms "
                                    f"(dropped: {dict(self.rx.dropped) or 'none'})", "state-timeout")

    def _pace(self, sent: bool) -> float:
        """Wait for this tick's deadline; how late it came [s]. Lock-step: until the bridge has ticked (never late;
        ``sent``: the tick went with this tick's command)."""
        if self.realtime:
            wait_until(self.deadline)
            return time.monotonic() - self.deadline
        if not self._tick_lockstep(sent=sent):
            self._taken_over()
            raise LinkLostError(f"no valid state from the bridge: it did not answer tick {self.wire.clock - 1} of the "
                                f"lock-step clock within {LOCKSTEP_REPLY_S:g} s of wall time", "tick-unanswered")
        return 0.0

    def _taken_over(self) -> None:
        """Stop if the bridge said another host's session took this one over (the robot is no longer this run's)."""
        if self.wire.ended is not None:
            raise SessionTakenOverError(self.wire.where, self.wire.ended)

    def estop(self) -> None:
        """Tell the bridge to hold the robot now (and latch its e-stop)."""
        self._estop_sent = True
        self._send(np.zeros(self.n), CMD_ESTOP)

    def latch_estop(self, reason: str) -> bool:
        """Latch the e-stop at the robot; this session's stop is the safety layer's, in its category."""
        self._send(self.tau, CMD_LATCH)
        return True

    def latched_estop(self) -> str | None:
        """The robot's latch at the bridge, as its newest state says."""
        return self.estop_name if self.status & ESTOPPED else None

    def provenance(self) -> dict[str, str]:
        """The bridge this run drove and the session's key id (the safety log's run record)."""
        return self.wire.provenance()

    @property
    def holding(self) -> bool:
        return bool(self.status & HOLDING)

    def run_metrics(self, trace) -> dict[str, float]:
        return link_metrics(self)

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per tick: lateness of the loop, and the newest round trip measured by then [ms]."""
        return link_series(self)

    def close(self) -> None:
        """The run's end, however it came (the robot already at rest: the safety layer's stop): the bridge this run
        started stopped, the link closed; SIGINT and SIGTERM held off meanwhile."""
        with signals_held():
            try:
                stop_bridge(self.process)  # the bridge first: nothing below may leave it running
            finally:
                self.wire.close()
                if self.frames is not None:
                    self.frames.close()


@hookimpl
def rehabkit_register_backends(registry) -> None:
    registry.add("hardware", config=HardwareConfig, factory=HardwareBackend)
