"""What a simulated drive watches its master by: the heartbeat consumer (0x1016) and the SYNC watchdog, each on a
clock given to it (``now`` [s]: the wall clock in real time, the device's own clock on a lock-step bus, a test's).

- Heartbeat consumer (CiA 301): writing a producer's node id and consumer time into 0x1016 sets it up; it becomes
  active with the first heartbeat that producer sends after that, and reports it lost once silent longer than its
  time — once: then it waits for the next heartbeat, which activates it again. Writing 0 disarms it.
- SYNC watchdog: armed while the drive takes SYNCs in OPERATIONAL with its power stage on, fed by each such SYNC;
  it reports the SYNC lost once when none came within its timeout, then stays disarmed until the next SYNC arms it.

Neither fires on its own: whoever keeps the clock polls them (:class:`Watchdog`: a thread on the wall clock). Each
is fed with when a frame *arrived* (``at``; :mod:`~rehabkit.canopen.simulated.arrivals`), the time it is handled
where none is given, and keeps what it fired for (``fired``: the silence each time [s]).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS

EPS = 1e-9  # [s] (a clock counted in µs, as floats: 10 ms is not more than 10 ms)


class HeartbeatConsumer:
    """The producers a device watches (0x1016); ``on_lost(node)``: one fell silent."""

    def __init__(self, now: Callable[[], float], on_lost: Callable[[int], None]):
        self.now, self.on_lost = now, on_lost
        self.limits: dict[int, float] = {}  # producer → its consumer time [s]
        self.heard: dict[int, float] = {}  # an active producer → its last heartbeat [s]; absent: waiting for one
        self.fired: list[float] = []  # the silence each time one was reported lost [s]
        self._lock = threading.Lock()

    def configure(self, node: int, ms: int) -> None:
        """``node`` watched for ``ms`` from its next heartbeat on (0: no longer watched)."""
        with self._lock:
            self.heard.pop(node, None)
            if ms:
                self.limits[node] = ms * 1e-3
            else:
                self.limits.pop(node, None)

    def clear(self) -> None:
        with self._lock:
            self.limits.clear()
            self.heard.clear()

    def heartbeat(self, node: int, at: float | None = None) -> bool:
        """A heartbeat from ``node`` (arrived ``at``, else now): its consumer active from then. Returns whether it had
        been lost (or not yet active) and is now active again."""
        with self._lock:
            if node not in self.limits:
                return False
            back = node not in self.heard
            self.heard[node] = max(self.heard.get(node, -math.inf), self.now() if at is None else at)
            return back

    def poll(self) -> None:
        """Every active producer silent longer than its time: reported, and waiting for its next heartbeat."""
        now = self.now()
        with self._lock:
            lost = [n for n, t in self.heard.items() if now - t > self.limits[n] + EPS]
            for n in lost:
                self.fired.append(now - self.heard.pop(n))
        for n in lost:
            self.on_lost(n)


class SyncWatchdog:
    """A drive's SYNC watchdog: ``timeout_s`` without a SYNC while armed, reported once."""

    def __init__(self, now: Callable[[], float], timeout_s: float = SYNC_TIMEOUT_MS * 1e-3):
        self.now, self.timeout_s = now, timeout_s
        self.last: float | None = None  # the last SYNC taken while armed [s]; None: disarmed
        self.fired: list[float] = []  # the silence each time it fired [s]

    def feed(self, armed: bool, at: float | None = None) -> None:
        """A SYNC taken (arrived ``at``, else now): armed from then (or not, where the drive's state does not arm
        it)."""
        self.last = (self.now() if at is None else at) if armed else None

    def expired(self, armed: bool) -> bool:
        """Whether it fires now (once: it is disarmed until the next SYNC arms it); ``armed``: the drive's state
        still arms it."""
        if not armed:
            self.last = None
        now = self.now()
        if self.last is None or now - self.last <= self.timeout_s + EPS:
            return False
        self.fired.append(now - self.last)
        self.last = None
        return True


class Watchdog:
    """A thread calling ``step()`` every ``period_s`` of wall time until :meth:`stop`; ``woke_late``: the most its
    wake-up came after it was due [s] (its own process's worst stall, as a sleeping thread sees it)."""

    def __init__(self, step: Callable[[], None], period_s: Callable[[], float], name: str = "watchdog"):
        self.step, self.period_s = step, period_s
        self._done = threading.Event()
        self.woke_late = 0.0
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Watchdog:
        self.thread.start()
        return self

    def stop(self) -> None:
        self._done.set()

    def _run(self) -> None:
        while True:
            period = self.period_s()
            due = time.monotonic() + period
            if self._done.wait(period):
                return
            self.woke_late = max(self.woke_late, time.monotonic() - due)
            self.step()
