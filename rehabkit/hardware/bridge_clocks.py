"""The bridge's two clocks: the wall's (a robot's drives tick on it) and the host's (lock-step, for a simulated
plant: deterministic, as fast as both ends compute)."""

from __future__ import annotations

import math
import os
import time

import numpy as np

from rehabkit.hardware.bridge import Bridge
from rehabkit.hardware.keypad import handle
from rehabkit.hardware.link.clock import SPIN_S, Lateness, wait_until
from rehabkit.hardware.link.protocol import CLEAR, CLOCK, CMD_RESET, COMMAND, HEADER, link_tick


def serve(bridge: Bridge, duration: float | None = None, parent: int | None = None) -> None:
    """Tick in real time until ``duration``, interrupted, or — given ``parent`` — once that process is gone (a bridge a
    host started must not outlive it). Each tick runs on its deadline with the commands gathered since the last one;
    between ticks the link is read as datagrams come (at most ``PER_TICK`` a socket: whatever arrives, the next tick
    is not late for it), then the loop spins to the deadline. How late each tick began: ``bridge.lateness``."""
    period = bridge.plant.timestep
    bridge.lateness = lateness = Lateness(period)
    start = time.monotonic()
    deadline = start
    ticks = 0
    inbox: list = []
    try:
        while duration is None or deadline - start < duration:
            ticks += 1
            now = time.monotonic()
            lateness.add(now - deadline)
            # on its deadline first: the commands gathered since the last tick, watchdog, plant step, state out
            bridge.tick(now, inbox)
            if parent is not None and ticks % 500 == 0 and os.getppid() != parent:
                return
            bridge.reloaded()
            if bridge.keypad is not None and ticks % 50 == 0:
                handle(bridge, bridge.keypad.poll(), time.monotonic())
            deadline += period
            # then what comes until the next deadline, read as it comes (bounded per socket: a flood waits)
            inbox = bridge.link.gather(deadline - SPIN_S)
            wait_until(deadline)
    finally:
        bridge.link.close()


def _resets(plain: bytes) -> bool:
    """An opened datagram is a host's reset (a COMMAND with ``CMD_RESET``)."""
    fields = HEADER.unpack_from(plain)
    return fields[2] == COMMAND and bool(fields[9] & CMD_RESET)


def serve_lockstep(bridge: Bridge, duration: float | None = None, parent: int | None = None) -> None:
    """Tick when the host's clock says so, not the wall's: each tick from the host (a command carrying it, or a bare
    CLOCK) is one tick at the time it carries (with the commands that arrived before it), answered by the state
    carrying the clock back (a bare CLOCK if the state goes elsewhere or nowhere). A new host's reset starts the clock
    afresh. The keypad is read between datagrams, whether a host ticks the bridge or not. ``duration`` is link time;
    with ``parent`` the bridge stops once that process is gone."""
    bridge.lockstep = True
    inbox: list[tuple[bytes, tuple]] = []
    last_tick = -math.inf  # the newest tick done
    owner = None  # whose clock that was: the host's address and session (a new host's reset starts a clock afresh)
    link = bridge.link
    keypad = bridge.keypad
    try:
        while True:
            got = link.next(0.5, None if keypad is None or keypad.closed else keypad.fd)
            bridge.reloaded()
            if keypad is not None:  # (read whether a host ticks or not: a person's keys are no clock's)
                handle(bridge, keypad.poll(), last_tick if last_tick > -math.inf else 0.0)
            if got is None:
                if parent is not None and os.getppid() != parent:
                    return
                continue
            data, addr = got
            plain = link.open(data, addr)
            if plain is None:
                continue
            if plain[3] == CLEAR:  # a person's act, not the clock's: done now, and answered with the status
                bridge.receive(last_tick, [(plain, addr)])
                bridge.status_to(addr)
                continue
            tick = link_tick(plain, bridge.robot_id)
            if tick is None or not tick[1]:
                inbox.append((plain, addr))
            if tick is None:
                continue
            now = tick[0]
            if duration is not None and now >= duration:
                return
            # a new session's clock, afresh: one that goes back, or another host's (its first tick may be the same
            # time as the last one done: a host refused at a latched e-stop, then the next after the clear)
            if (now < last_tick or (addr, len(link.sessions)) != owner) and any(_resets(p) for p, _ in inbox):
                last_tick = -math.inf
            if now <= last_tick:  # the host asks again (its tick or our answer was lost): answer again, the tick
                inbox = []  # done once (its command, the same again, not applied twice)
                bridge.repeated_ticks += 1
                if bridge.answer is not None:
                    link.send(bridge.answer, addr)
                continue
            last_tick, owner = now, (addr, len(link.sessions))
            answered = bridge.tick(now, inbox) and bridge.peer == addr
            inbox = []
            if not answered:
                bridge.answer = (CLOCK, np.zeros(0), now + bridge.plant.timestep, 0.0, 0, 0, None, None)
                link.send(bridge.answer, addr)
    finally:
        link.close()
