"""The bus's cycles on the wall clock: enabled drives expect a SYNC every cycle, whatever the host is doing.

The control loop's steps make the cycles, each at its deadline. When a step is more than two cycles late — the host
stalled, or no step is coming: between the reset and the loop's first step (the run's first plan comes between),
after the last — a thread of this clock makes the cycle instead, holding the posture the robot was at when the hold
began as the bridge does (PD to it with gravity compensation), until the next step. A hold a step ended is counted
(the run's interventions, as the bridge's holds through gaps in the commands); one still open at the end is the run's
end, not a gap.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from rehabkit.hardware.link.clock import wait_until

HOLD_AFTER_CYCLES = 2  # a step this late is not coming in time: the drives get their SYNC from the hold

class CycleClock:
    """Cycles every ``period`` [s]: ``cycle(tau)`` runs one; ``hold(q_hold)`` is the torque that holds ``q_hold``
    from the newest state."""

    def __init__(self, period: float, cycle: Callable[[np.ndarray], None],
                 hold: Callable[[np.ndarray], np.ndarray], posture: Callable[[], np.ndarray]):
        self.period, self._cycle, self._hold, self._posture = period, cycle, hold, posture
        self.deadline = time.monotonic()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._paused = False
        self._hold_q: np.ndarray | None = None
        self.holds: list[list[int]] = []  # [the loop's steps before it, cycles] of each hold a step ended, in the loop
        self._open: list[int] | None = None
        self.steps = 0
        self.late = 0  # steps that came after their cycle's deadline had passed by a cycle
        self._thread = threading.Thread(target=self._run, name="canopen-cycles", daemon=True)

    def start(self, tau: np.ndarray) -> None:
        """The first cycle now (with ``tau``), then held until the first step."""
        # the holding thread must get the interpreter within a cycle, the loop's thread busy or not (Python hands it
        # over every 5 ms by default: longer than a 2 ms cycle)
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch, self.period / 4))
        self.deadline = time.monotonic()
        self.step(tau, count=False)
        self._thread.start()

    def step(self, tau: np.ndarray, count: bool = True) -> None:
        """The loop's cycle: at its deadline (at once if that has passed)."""
        wait_until(self.deadline)
        with self._lock:
            if count and time.monotonic() - self.deadline > self.period:
                self.late += 1
            if self._open is not None:  # the loop takes over from a hold (before its first step: the set-up's)
                if self._open[0] > 0:
                    self.holds.append(self._open)
                self._open, self._hold_q = None, None
            self.steps += count
            self.deadline += self.period
            self._cycle(tau)

    def pause(self, seconds: float) -> None:
        """This host stalls for ``seconds``: no cycle at all meanwhile (an injected fault: the drives lose SYNC)."""
        with self._lock:
            self._paused = True
            time.sleep(seconds)
            self.deadline = time.monotonic()
            self._paused = False

    def _run(self) -> None:
        while True:
            due = self.deadline
            if self._closing.wait(max(0.0, due + HOLD_AFTER_CYCLES * self.period - time.monotonic())):
                return
            with self._lock:
                if self.deadline != due or self._paused or self._closing.is_set():
                    continue  # (a step took it)
                if self._open is None:
                    self._hold_q, self._open = self._posture().copy(), [self.steps, 0]
                self._open[1] += 1
                self.deadline += self.period
                self._cycle(self._hold(self._hold_q))

    def close(self) -> None:
        self._closing.set()
        if self._thread.is_alive():
            self._thread.join()
            sys.setswitchinterval(self._switch)


def own_gravity(robot):
    """``gravity(q)`` for another thread than the run's: Pinocchio's on a workspace of its own where the robot uses
    Pinocchio's default (its ``Data`` is not shared: two threads in one would read each other's half-written
    values), else the robot's own (a robot overriding ``gravity_torque`` keeps no Pinocchio workspace)."""
    from rehabkit.core.kinds.interfaces import Robot

    if type(robot).gravity_torque is not Robot.gravity_torque:
        return robot.gravity_torque
    import pinocchio as pin

    model = robot.model.pin_model
    data = model.createData()
    return lambda q: pin.computeGeneralizedGravity(model, data, np.asarray(q, float))
