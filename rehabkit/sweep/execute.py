"""One run of a sweep, as a row: settings, seed, metrics, expectations, wall time, error.

This is the function Ray ships to its workers (and the serial loop calls). It never
raises for a failing run: the error becomes part of the row, and the sweep goes on.
"""

from __future__ import annotations

import gc
import signal
import threading
import time
import weakref
from pathlib import Path
from typing import Any

from rehabkit.core.kinds.metric import wall_clock


# figures that measure the machine, not the run: they differ between any two executions
class RunTimeoutError(BaseException):
    """A run took longer than the sweep allows (a BaseException: plugin-error handlers must not catch it)."""


def error_fields(exc: BaseException) -> dict[str, Any]:
    """A failed run's error as fields, beside the row's ``error`` (its words): ``error_type``, the error's class name;
    ``error_missing``, the capabilities (protocol names, sorted) its plugins needed that the robot or backend lacks,
    where that is why (a :class:`~rehabkit.core.setup.errors.PluginSetupError`'s ``missing``), else None."""
    missing = getattr(exc, "missing", None)
    lacked = sorted({cap.__name__ for caps in missing.values() for cap in caps}) if missing else None
    return {"error_type": type(exc).__name__, "error_missing": lacked}


def execute(path: str, overrides: dict[str, Any], timeout_s: float | None = None,
            out_dir: str | None = None) -> dict[str, Any]:
    """Run the scenario with ``overrides``; the row (never raises for the run's own failures). With ``out_dir``
    the run writes its outputs there, as ``rehabkit run --out`` does."""
    from rehabkit.core.run.runner import Runner  # in the worker: plugins load once per process
    from rehabkit.core.scenario.loader import load_scenario

    t0 = time.perf_counter()
    row: dict[str, Any] = {"error": None}
    alarm = timeout_s is not None and threading.current_thread() is threading.main_thread()
    if alarm:  # in-process runs (the serial loop): SIGALRM interrupts the run's Python code
        def expire(signum, frame):
            raise RunTimeoutError(f"timeout: still running after {timeout_s:g} s")
        previous = signal.signal(signal.SIGALRM, expire)
        signal.setitimer(signal.ITIMER_REAL, timeout_s)
    setup = None  # the run's plugins, watched: freed with the run, or collected
    try:
        runner = Runner(load_scenario(Path(path), overrides), out_dir=Path(out_dir) if out_dir else None)
        result = runner.run()
        setup = weakref.ref(runner.setup)
        del runner
        row["passed"] = result.passed
        row["ended"] = ended = result.summary["ended"]  # (interrupted: Ctrl-C, SIGTERM; the sweep stops once recorded)
        if ended["how"] == "interrupted":
            row["error"] = f"interrupted ({ended.get('signal')}) at t={ended.get('t')} s"
        # NaN (a measure with nothing to measure) as None, as the stored rows have it
        row["metrics"] = {k: None if v != v else float(v) for k, v in result.metrics.items()
                          if isinstance(v, (int, float))}
        row["expectations"] = {e["metric"]: bool(e["passed"]) for e in result.summary["expectations"]}
        row["wall_clock"] = sorted(wall_clock(result.summary.get("metric_info", {})))  # as the run described them
        del result
    except (Exception, RunTimeoutError) as exc:  # noqa: BLE001 (recorded: the sweep goes on)
        row.update(passed=False, metrics={}, expectations={}, error=f"{type(exc).__name__}: {exc}",
                   **error_fields(exc))
    finally:
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    # a run is freed by reference counting; where a plugin's reference cycle (or a failure's traceback) holds it,
    # its scene (a MuJoCo model of ~100 MB with a musculoskeletal arm) would wait for a full collection the small
    # Python side never triggers: a worker running one scenario after another grew ~140 MB a run
    if setup is None or setup() is not None:
        gc.collect()
    row["wall_time_s"] = time.perf_counter() - t0
    return row
