"""Slow sensors read in their own threads when the loop runs in wall-clock time.

A camera frame takes tens of milliseconds to grab and process; on a real-time backend the
control loop must not wait for it. A sensor that says it is ``blocking`` is then read in a
thread of its own: the loop starts a reading when one is due (skipping it, and counting an
overrun, while the previous one is still in progress) and takes the reading, stamped with
the time it was started, at the first tick after it is done. In simulation time stands
still while a sensor reads, so there every reading stays in the loop.
"""

from __future__ import annotations

import sys
from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from rehabkit.core.kinds.interfaces import Backend, Sensor

SWITCH_INTERVAL_S = 2e-4  # how long a sensor thread may hold the interpreter before the loop gets it back


class SensorThreads:
    """One worker thread per blocking sensor."""

    def __init__(self, names: list[str], prepare: Callable[[dict], dict] | None = None):
        self._names = set(names)
        self._pool = {name: ThreadPoolExecutor(1, thread_name_prefix=f"rehabkit-sensor-{name}") for name in names}
        self._pending: dict[str, tuple[float, Future]] = {}
        self._prepare = prepare  # work on a finished reading that belongs in its thread too (e.g. image encoding)
        self.overruns: Counter = Counter()
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)  # the default 5 ms would let a sensor thread delay a tick

    def __contains__(self, name: str) -> bool:
        return name in self._names

    @property
    def busy(self) -> bool:
        return bool(self._pending)

    def start(self, name: str, sensor: Sensor, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> None:
        """Start a reading, unless the previous one is still in progress."""
        if name in self._pending:
            self.overruns[name] += 1
            return
        self._pending[name] = (t, self._pool[name].submit(self._read, sensor, t, q.copy(), qd.copy(), backend))

    def _read(self, sensor: Sensor, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, Any]:
        reading = sensor.read(t, q, qd, backend)
        return reading if self._prepare is None else self._prepare(reading)

    def finished(self) -> list[tuple[str, float, dict[str, Any]]]:
        """Readings done since the last call: (sensor, time started, reading); a sensor's exception is raised."""
        done = [name for name, (_, fut) in self._pending.items() if fut.done()]
        return [(name, t, fut.result()) for name in done for t, fut in [self._pending.pop(name)]]

    def close(self) -> None:
        """Wait for readings in progress, stop the threads."""
        for pool in self._pool.values():
            pool.shutdown(wait=True, cancel_futures=True)
        self._pool.clear()
        self._pending.clear()
        sys.setswitchinterval(self._switch)
