"""The bus's cycles on the wall clock: enabled drives expect a SYNC every cycle, whatever the host is doing.

The control loop's steps make the cycles, each at its deadline. When a step is more than two cycles late — the host
stalled, or no step is coming: between the reset and the loop's first step (the run's first plan comes between),
after the last — a thread of this clock makes the cycle instead, holding the posture the robot was at when the hold
began as the bridge does (PD to it with gravity compensation), until the next step. A hold a step ended is counted
(the run's interventions, as the bridge's holds through gaps in the commands); one still open at the end is the run's
end, not a gap.

While the cycles run the process keeps their deadlines as :mod:`~rehabkit.canopen.deadlines` says (the collector
held, the loop's, the hold's and the bus readers' threads in the real-time class, the host on CPUs of its own: each
where permitted), undone at :meth:`CycleClock.close`.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from rehabkit.canopen import deadlines
from rehabkit.canopen.deadlines import HOLD_AFTER_CYCLES
from rehabkit.hardware.link.clock import wait_until


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
        self._started = False

    def keep_deadlines(self) -> None:
        """This process keeps the cycles' deadlines from now on (:mod:`~rehabkit.canopen.deadlines`; undone at
        :meth:`close`): at :meth:`start`, or before it — before the drives are enabled, so that the set-up's cycles
        with their power stages on are kept too."""
        if self._started:
            return
        self._started = True
        # the holding thread must get the interpreter within a cycle, the loop's thread busy or not (Python hands it
        # over every 5 ms by default: longer than a 2 ms cycle)
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch, self.period / 4))
        self._cpus = deadlines.pin("host")
        self._gc_held = deadlines.hold_collector()
        self._realtime = deadlines.cycle_threads()
        # the hold and the bus readers above the loop's thread: on one CPU a real-time thread is not preempted by
        # one of its own priority, and the loop's may compute for long (after its last step, the run's end)
        self._fifo = deadlines.realtime(self._realtime[:1], deadlines.HOST_PRIORITY) and deadlines.realtime(
            self._realtime[1:], deadlines.HOST_PRIORITY + 1)

    def start(self, tau: np.ndarray) -> None:
        """The first cycle now (with ``tau``), then held until the first step."""
        self.keep_deadlines()
        self.deadline = time.monotonic()
        self.step(tau, count=False)
        self._thread.start()
        self._realtime.append(self._thread)
        if self._fifo:
            deadlines.realtime([self._thread], deadlines.HOST_PRIORITY + 1)

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

    def stop(self) -> None:
        """No more cycles of this clock's own (the process still keeps their deadlines: the run's end cycles on)."""
        self._closing.set()
        if self._thread.is_alive():
            self._thread.join()

    def close(self) -> None:
        """The cycles end: the thread stopped, the process as it was before :meth:`keep_deadlines`."""
        self.stop()
        if self._started:
            self._started = False
            sys.setswitchinterval(self._switch)
            deadlines.unpin(self._cpus)  # (first: on one CPU, in the ordinary class, its threads wait on each other)
            deadlines.ordinary(self._realtime)
            if self._gc_held:
                deadlines.release_collector()


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
