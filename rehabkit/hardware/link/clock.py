"""Waiting on a general-purpose OS: for a loop's next deadline (host loop and bridge alike), and for a datagram; and
how late a loop's ticks came (:class:`Lateness`)."""

from __future__ import annotations

import math
import os
import select
import socket
import time

SPIN_S = 2e-4  # sleep until this close to the deadline (the OS wakes a sleeper late), then spin
# poll this long for a datagram before sleeping on it: a process woken by one takes ~0.3 ms on this VM (measured:
# a UDP ping-pong between two processes 283 µs per exchange asleep, 28 µs polling), longer than a lock-step tick
# Polling pays only with a core to spare: on a machine whose cores are all busy (a test suite's parallel workers) the
# poller takes the core the other end needs to answer; REHABKIT_LINK_POLL_S=0 then waits asleep from the start.
POLL_S = float(os.environ.get("REHABKIT_LINK_POLL_S", 1e-3))


def wait_until(deadline: float) -> None:
    """Return at ``deadline`` (``time.monotonic`` seconds), or at once if it has passed."""
    while (left := deadline - time.monotonic()) > 0:
        if left > SPIN_S + 1e-4:
            time.sleep(left - SPIN_S)


def wait_readable(sock: socket.socket | list[socket.socket], timeout: float, poll: float | None = None) -> bool:
    """True once ``sock`` (or one of several) has a datagram to read, False after ``timeout`` seconds without one."""
    socks = [sock] if isinstance(sock, socket.socket) else sock
    start = time.monotonic()
    poll_end = start + min(POLL_S if poll is None else poll, timeout)
    while time.monotonic() < poll_end:
        if select.select(socks, [], [], 0)[0]:
            return True
    left = start + timeout - time.monotonic()
    return left > 0 and bool(select.select(socks, [], [], left)[0])


class Lateness:
    """How late a paced loop's ticks began after their deadlines, kept in 0.1 ms bins (a loop that runs for days keeps
    a fixed few kilobytes): the count, the worst, the 99th percentile, the ticks a period or more late."""

    BIN_S, BINS = 1e-4, 5000  # up to 0.5 s in bins; later than that is counted in the last one (the worst is exact)

    def __init__(self, period: float):
        self.period, self.bins, self.worst = period, [0] * self.BINS, 0.0

    def add(self, late: float) -> None:
        late = max(0.0, late)
        self.bins[min(self.BINS - 1, int(late / self.BIN_S))] += 1
        self.worst = max(self.worst, late)

    def summary(self) -> dict:
        ticks = sum(self.bins)
        p99, seen = 0.0, 0
        for i, n in enumerate(self.bins):
            seen += n
            if seen >= math.ceil(0.99 * ticks):
                p99 = (i + 1) * self.BIN_S
                break
        over = sum(self.bins[min(self.BINS - 1, int(self.period / self.BIN_S)):])
        return {"ticks": ticks, "late_max_ms": round(1e3 * self.worst, 3),
                "late_p99_ms": round(1e3 * min(p99, self.worst), 3), "late_a_period": over}
