"""The robot-side bridge: the program next to a robot's drives, serving the host over UDP.

Each tick (the plant's rate, 1 kHz by default) it applies the newest valid command, steps the plant, and sends the
state back with the echo of the command it used. Commands pass the protocol's checks (``protocol.Receiver``) and are
clipped to the effort limits.

A torque is only right for the state it was computed at, so the bridge never applies one open-loop for long: after
``stale_s`` of its own ticks without a newer command (a host stall, lost packets) it holds the posture it is at (PD
to it plus gravity; status bit ``STALE``) until the next command, which resumes torque control at once. Ticks, not
wall time, count here, so a bridge catching up after a stall of its own holds too. If no valid command arrives for
``watchdog_s`` while running, or an e-stop command comes, the hold is latched (status ``HOLDING``) and only a reset
from the host re-enables the robot. An e-stop (a host's, or the button at the robot: :meth:`Bridge.press_estop`, or
the bridge's keypad: ``e``) is latched further, in the bridge's latch file (:mod:`rehabkit.core.safety.estop`):
across sessions and restarts, resets are refused (status ``ESTOPPED``) until a person clears it (a ``CLEAR`` with
their name from ``rehabkit estop clear --bridge``: in an authenticated session when the bridge has a key; the
keypad's ``c``; or the latch file cleared while the bridge is down); the session after that tells the host to ramp
in (status ``RAMP_IN``). Given the run's joint limits, the bridge is also a backstop to the host's safety layer: a
joint beyond its range or speed by more than a margin (wider than the host's, which acts first) latches the hold too
(status ``LIMIT``), whatever the host is doing. Real drives plug in as another
:class:`~rehabkit.hardware.plant.Plant`; :class:`~rehabkit.hardware.plant.MujocoPlant` is the robot's MuJoCo model
as the plant, for tests and hardware-in-the-loop rehearsal.

Given the robot's key (``key``), the bridge serves authenticated sessions only (:mod:`rehabkit.hardware.security`):
a datagram that is not authentic, or was seen before, is counted by reason and never applied, never resets, never
clears and never feeds the watchdog.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rehabkit.core.safety.estop import EStopLatch
from rehabkit.core.safety.stopping import stable_gains
from rehabkit.hardware.bridge_limits import BridgeLimits
from rehabkit.hardware.keypad import Keypad
from rehabkit.hardware.link.bridge_end import BridgeLink
from rehabkit.hardware.link.protocol import (
    CLEAR,
    CLEAR_AT_KEYPAD,
    CLEAR_BY_KEY,
    CLEARED,
    CMD_BRAKE,
    CMD_COMPLIANT,
    CMD_ESTOP,
    CMD_LATCH,
    CMD_RESET,
    ENABLED,
    ESTOPPED,
    HOLDING,
    LIMIT,
    NO_RIGHT,
    RAMP_IN,
    STALE,
    STATE,
    TICK,
    WATCHDOG,
    clear_name,
)
from rehabkit.hardware.plant import Plant
from rehabkit.hardware.security.keys import LinkKey

HOLD_KP, HOLD_KD = 60.0, 6.0


class Bridge:
    """Serves one host over UDP at the plant's rate, with a command watchdog, an e-stop, a hold through gaps in
    the commands and (given ``limits``) its own limit check."""

    def __init__(self, plant: Plant, robot_id: int = 1, port: int = 0, host: str = "127.0.0.1",
                 watchdog_s: float = 0.005, stale_s: float = 0.010, limits: BridgeLimits | None = None,
                 latch: EStopLatch | None = None, keypad: Keypad | None = None, key: LinkKey | None = None,
                 clear_key: LinkKey | None = None, clear_right: str = "link", log=None):
        self.plant, self.robot_id, self.watchdog_s, self.limits = plant, robot_id, watchdog_s, limits
        self.latch, self.keypad = latch, keypad
        # who may clear a latched e-stop over the link: "link" any session, "key" one under ``clear_key`` only,
        # "keypad" none (the keypad at the robot only)
        self.clear_right = "key" if clear_key is not None else clear_right
        # (declared in every state: a host refused at a latched e-stop says what clears it here)
        self.declares = {"key": CLEAR_BY_KEY, "keypad": CLEAR_AT_KEYPAD}.get(self.clear_right, 0)
        self._cleared_in = None  # (where from, session) of the clear that cleared a latched e-stop: CLEARED's
        self._sessions = 0  # new hosts' sessions seen (BridgeLink.sessions): a new one has no peer until it speaks
        self.stale_ticks = max(1, round(stale_s / plant.timestep))
        self.since_command = 0  # plant ticks since the newest torque command
        self.stale_holds: list[tuple[float, int]] = []  # (time, ticks) of each gap bridged by holding
        self.held_ticks = 0  # since the reset, sent with each state
        self.link = BridgeLink(robot_id, plant.joints, host, port, key, clear_key, log)
        self.port, self.rx = self.link.port, self.link.rx
        self.peer = None
        self.tau = np.zeros(plant.joints)
        self.status = 0
        self.hold_q: np.ndarray | None = None
        self._gains_at: np.ndarray | None = None  # the hold posture the gains were made for (_hold_gains)
        self._gains = (np.full(plant.joints, HOLD_KP), np.full(plant.joints, HOLD_KD))
        self.last_valid = -np.inf
        self.echo = 0.0
        self.answer = None  # the newest state (or bare clock) sent: a lock-step tick asked again is answered again
        self.repeated_ticks = 0  # lock-step ticks the host sent again (answered again, not done again)
        self.clears: list[dict] = []  # each e-stop clear: when, by whom, how (the link, its key id)
        self.trips: list[tuple[float, str]] = []  # (time, why) of each hold
        self.watchdog_ms: list[float] = []  # each watchdog hold: how long without a valid command when it latched
        self.lateness = None  # real time: how late its ticks began (bridge_clocks.serve keeps it)
        self.reload = False  # SIGHUP came: read the key file again (at the loop's next turn, not in the handler)
        self.waiting = False  # reset done, no torque command yet: holding the start posture
        self.lockstep = False  # ticked by the host's clock (serve_lockstep), not the wall's
        self._state = np.zeros((3, plant.joints))  # the STATE message's rows, reused
        self._ramp_next = False  # the latch was cleared: the next session ramps in
        self.braked = False
        self.compliant = False  # the host yields (CMD_COMPLIANT): a gap in the commands is bridged without stiffness
        plant.gravity(plant.read()[0])  # (its first call imports the dynamics: here, not in a tick)
        if latch is not None and latch.latched() is not None:  # latched before this bridge started
            self.status = HOLDING | ESTOPPED
            self.hold_q = plant.read()[0]

    def _hold(self, now: float, why: str, bit: int) -> None:
        if not self.status & HOLDING:
            self.trips.append((now, why))
            if self.hold_q is None or self.waiting:  # (a stale-command hold keeps its posture)
                self.hold_q = self.plant.read()[0]
            self.waiting = False
        self.status = (self.status | HOLDING | bit) & ~(ENABLED | STALE)

    def _press(self, reason: str, by: str, source: str | None = None) -> None:
        if self.latch is not None:
            self.latch.press(reason, by, source)

    def press_estop(self, now: float, by: str = "the e-stop button at the robot", source: str = "button") -> None:
        """The e-stop at the robot: held at once, latched until cleared. ``source``: the device pressed, as the latch
        file's ``source`` (``button``; the keypad's ``e``: ``keypad``)."""
        self._press(by, "robot", source)
        self._hold(now, "e-stop", ESTOPPED)

    def clear_estop(self, by: str, source: tuple | None = None, **how: str) -> bool:
        """A person (``by``) cleared the e-stop (``how``: over which link, recorded with it; ``source``: the address
        the clear came from): the robot stays held until the host's next reset, which then ramps in. Whether a latched
        e-stop was cleared (else nothing was latched: its states then say "not latched", unless the clear that did
        clear it is sent again, its answer lost)."""
        was = self.latch.clear(by, **how) if self.latch is not None else None
        latched = bool(self.status & ESTOPPED) or was is not None
        if self.status & ESTOPPED or self.latch is not None:  # (the bridge's own record of who cleared it, how)
            self.clears.append({"at": time.time(), "by": by, "latched": bool(self.status & ESTOPPED), **how})
            print(f"bridge: e-stop {'cleared' if latched else 'clear (not latched)'} by {by} "
                  f"({', '.join(f'{k} {v}' for k, v in how.items()) or 'here'})", file=sys.stderr, flush=True)
        self.status &= ~NO_RIGHT
        if latched:  # its states say so until the next reset (a clear where nothing was latched: not latched)
            self.status |= CLEARED
            self._cleared_in = (source, how.get("session"))
        elif source is None or (source, how.get("session")) != self._cleared_in:
            self.status &= ~CLEARED
        if self.status & ESTOPPED:
            self.status = (self.status & ~ESTOPPED) | HOLDING
            self.status &= ~ENABLED
            self._ramp_next = True
        return latched

    def receive(self, now: float, inbox: list[tuple[bytes, tuple]]) -> None:
        if len(self.link.sessions) != self._sessions:  # a new host's session: its states go to it once it speaks
            self._sessions, self.peer = len(self.link.sessions), None
        for plain, addr in inbox:
            if not self.link.current(plain):  # read in a session that has ended since (another host's took it over)
                self.rx.dropped["ended-session"] += 1
                continue
            if plain[3] == CLEAR:
                name = clear_name(plain, self.robot_id)
                if name is None:
                    self.rx.dropped["clear"] += 1
                    continue
                self.peer = addr
                if self.clear_right == "keypad" or self.clear_right == "key" and self.link.right != "clear":
                    self.link.refused(addr, "clear-right")  # (its states say so: NO_RIGHT, until the next reset)
                    self.status |= NO_RIGHT
                    continue
                self.clear_estop(name, addr, via=f"the link from {addr[0]}", key_id=self.link.key_id,
                                 session=self.link.session_id)
                continue
            if self.link.right != "drive":  # a clearing key's session clears, and does nothing else
                self.link.refused(addr, "clear-only")
                continue
            msg = self.rx.take(plain, now)
            if msg is None:
                continue
            self.peer, self.echo = addr, msg.sent_at
            if msg.status & CMD_RESET:  # also the way back from a hold: held at q0 until the first command
                if self.status & ESTOPPED:  # latched: no session starts, the robot stays held where it is
                    continue
                self.plant.reset(msg.values)
                self.tau[:] = 0.0
                # a reset sent again (its answer late: a loaded host resends) keeps the ramp-in the first one took
                again = self.waiting and bool(self.status & RAMP_IN)
                ramp = self._ramp_next or again or (self.latch is not None and self.latch.take_ramp_in())
                self.hold_q, self.status, self.last_valid = msg.values.copy(), ENABLED | (RAMP_IN if ramp else 0), \
                    np.inf
                self.waiting, self.since_command, self.held_ticks, self._ramp_next = True, 0, 0, False
                self.braked = self.compliant = False
                continue
            self.last_valid = now
            self.compliant = bool(msg.status & CMD_COMPLIANT)
            if msg.status & CMD_BRAKE and not self.braked:
                self.braked = self.plant.brake()
            if msg.status & CMD_LATCH:  # the host's e-stop: it stops the robot now, the latch keeps it stopped
                self._press("e-stop at the host (its safety layer stops the robot)", "host")
                self.status |= ESTOPPED
            if msg.status & CMD_ESTOP:
                self._press("e-stop command from the host", "host")
                self._hold(now, "e-stop", ESTOPPED)
            elif self.status & ENABLED:
                if self.waiting or self.status & STALE:  # the host's torques take over (again) from the hold
                    self.hold_q, self.waiting = None, False
                    self.status &= ~STALE
                self.since_command = 0
                self.tau = np.clip(msg.values, -self.plant.effort, self.plant.effort)

    def tick(self, now: float, inbox: list[tuple[bytes, tuple]] | None = None) -> bool:
        """One cycle: commands in (``inbox``: those gathered since the last tick, by the real-time loop or a lock-step
        clock; else what arrived, read now for a bounded time), watchdog, torques, plant step, state out (in lock-step
        carrying the clock's answer); False if there was no peer to send it."""
        self.receive(now, self.link.arrived() if inbox is None else inbox)
        if self.status & ENABLED and self.last_valid != np.inf and now - self.last_valid > self.watchdog_s:
            self.watchdog_ms.append(1e3 * (now - self.last_valid))
            self._hold(now, f"no valid command for {self.watchdog_ms[-1]:.1f} ms", WATCHDOG)
        q, qd = self.plant.read()
        if self.limits is not None and self.status & ENABLED and (why := self.limits.breach(q, qd)):
            self._hold(now, why, LIMIT)
        if self.status & ENABLED and not self.waiting:
            self.since_command += 1
            if self.since_command > self.stale_ticks:
                if not self.status & STALE:  # the last torque is too old to apply: hold here until a new one
                    self.status |= STALE
                    self.hold_q = q.copy()
                    self.stale_holds.append((now, 0))
                t0, ticks = self.stale_holds[-1]
                self.stale_holds[-1] = (t0, ticks + 1)
                self.held_ticks += 1
        tau = self.tau
        if self.hold_q is not None:
            kp, kd = self._hold_gains()
            # a gap during the host's yield is bridged yielding (no stiffness toward where the gap began); a latched
            # hold (watchdog, e-stop, limit) always holds the posture
            stiff = 0.0 if self.compliant and not self.status & HOLDING else kp
            tau = np.clip(stiff * (self.hold_q - q) - kd * qd + self.plant.gravity(q),
                          -self.plant.effort, self.plant.effort)
        self.plant.apply(tau)
        self.plant.advance()
        if self.peer is None:
            return False
        q, qd = self.plant.read()
        sent = now + self.plant.timestep if self.lockstep else None  # (in lock-step the link's clock is time)
        state = self._state
        state[0], state[1], state[2] = q, qd, tau
        self.answer = (STATE, state.copy() if self.lockstep else state, sent, self.echo,
                        self.status | self.declares | (TICK if self.lockstep else 0), self.held_ticks,
                        self.plant.read_measured(), self.plant.read_instruments())
        self.link.send(self.answer, self.peer)
        return True

    def reloaded(self) -> None:
        """The key file read again if SIGHUP asked (the loop calls this each turn)."""
        if self.reload:
            self.reload = False
            print(f"bridge: SIGHUP: {self.link.reload_key()}", file=sys.stderr, flush=True)

    def _hold_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """The hold's PD gains per joint: HOLD_KP and HOLD_KD where the plant's tick can apply them stably for the
        joint's inertia where the hold began, less where it cannot (a light wrist held with a shoulder's damping
        swings wider each tick: 634 °/s within 3 ms on a 0.8 g·m² wrist), as the safety layer's own hold."""
        if self._gains_at is not self.hold_q:
            self._gains = stable_gains(HOLD_KP, HOLD_KD, self.plant.joint_inertia(), self.plant.timestep)
            self._gains_at = self.hold_q
        return self._gains

    def status_to(self, addr: tuple) -> None:
        """The state as it stands (status bits up to date), outside the lock-step clock's ticks."""
        q, qd = self.plant.read()
        self.link.send((STATE, np.stack([q, qd, self.tau]), None, self.echo, self.status | self.declares,
                        self.held_ticks, self.plant.read_measured(), self.plant.read_instruments()), addr)

    def link_stats(self) -> dict:
        """What the link accepted and refused, and its sessions (``rehabkit bridge --stats``)."""
        clock = {"clock": self.lateness.summary()} if self.lateness is not None else {}
        return {**self.link.stats(), "repeated_ticks": self.repeated_ticks, "estop_clears": self.clears,
                "watchdog_holds_ms": [round(ms, 3) for ms in self.watchdog_ms], **clock}
