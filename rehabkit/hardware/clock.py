"""Waiting on a general-purpose OS: for a loop's next deadline (host loop and bridge alike), and for a datagram."""

from __future__ import annotations

import select
import socket
import time

SPIN_S = 2e-4  # sleep until this close to the deadline (the OS wakes a sleeper late), then spin
# poll this long for a datagram before sleeping on it: a process woken by one takes ~0.3 ms on this VM (measured:
# a UDP ping-pong between two processes 283 µs per exchange asleep, 28 µs polling), longer than a lock-step tick
POLL_S = 1e-3


def wait_until(deadline: float) -> None:
    """Return at ``deadline`` (``time.monotonic`` seconds), or at once if it has passed."""
    while (left := deadline - time.monotonic()) > 0:
        if left > SPIN_S + 1e-4:
            time.sleep(left - SPIN_S)


def wait_readable(sock: socket.socket, timeout: float, poll: float = POLL_S) -> bool:
    """True once ``sock`` has a datagram to read, False after ``timeout`` seconds without one."""
    start = time.monotonic()
    poll_end = start + min(poll, timeout)
    while time.monotonic() < poll_end:
        if select.select([sock], [], [], 0)[0]:
            return True
    left = start + timeout - time.monotonic()
    return left > 0 and bool(select.select([sock], [], [], left)[0])
