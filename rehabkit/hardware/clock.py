"""Waiting for a loop's next deadline on a general-purpose OS (host loop and bridge alike)."""

from __future__ import annotations

import time

SPIN_S = 2e-4  # sleep until this close to the deadline (the OS wakes a sleeper late), then spin


def wait_until(deadline: float) -> None:
    """Return at ``deadline`` (``time.monotonic`` seconds), or at once if it has passed."""
    while (left := deadline - time.monotonic()) > 0:
        if left > SPIN_S + 1e-4:
            time.sleep(left - SPIN_S)
