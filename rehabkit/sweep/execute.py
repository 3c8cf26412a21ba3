"""One run of a sweep, as a row: settings, seed, metrics, expectations, wall time, error.

This is the function Ray ships to its workers (and the serial loop calls). It never
raises for a failing run: the error becomes part of the row, and the sweep goes on.
"""

from __future__ import annotations

import re
import signal
import threading
import time
from pathlib import Path
from typing import Any

# figures that measure the machine, not the run: they differ between any two executions
WALL_CLOCK = re.compile(r"(_ms$|^wall_time_s$|^setup_time_s$|^real_time_factor$|^joint_matrix_setup_s$|"
                        r"^deadline_|^link_|^states_dropped|^sensor_overruns_|^bridge_hold_at_s$)")


class RunTimeoutError(BaseException):
    """A run took longer than the sweep allows (a BaseException: plugin-error handlers must not catch it)."""


def execute(path: str, overrides: dict[str, Any], timeout_s: float | None = None) -> dict[str, Any]:
    """Run the scenario with ``overrides``; the row (never raises for the run's own failures)."""
    from rehabkit.api import run_scenario  # in the worker: plugins load once per process

    t0 = time.perf_counter()
    row: dict[str, Any] = {"error": None}
    alarm = timeout_s is not None and threading.current_thread() is threading.main_thread()
    if alarm:  # in-process runs (the serial loop): SIGALRM interrupts the run's Python code
        def expire(signum, frame):
            raise RunTimeoutError(f"timeout: still running after {timeout_s:g} s")
        previous = signal.signal(signal.SIGALRM, expire)
        signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        result = run_scenario(Path(path), overrides)
        row["passed"] = result.passed
        # NaN (a measure with nothing to measure) as None, as the stored rows have it
        row["metrics"] = {k: None if v != v else float(v) for k, v in result.metrics.items()
                          if isinstance(v, (int, float))}
        row["expectations"] = {e["metric"]: bool(e["passed"]) for e in result.summary["expectations"]}
    except (Exception, RunTimeoutError) as exc:  # noqa: BLE001 (recorded: the sweep goes on)
        row.update(passed=False, metrics={}, expectations={}, error=f"{type(exc).__name__}: {exc}")
    finally:
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    row["wall_time_s"] = time.perf_counter() - t0
    return row
