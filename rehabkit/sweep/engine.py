"""Run a sweep: skip what is done, run the rest serially or on Ray, record every run, write the tables.

Each finished run is saved at once, so a sweep that is killed resumes where it stopped. On
Ray at most one run per CPU of the cluster is in flight, so a run's submission is its start:
one that exceeds the timeout is cancelled (its worker killed) and recorded as failed. Rows
are kept in grid order whatever order the runs finish in, so a sweep gives the same table
serially and in parallel (wall-clock figures aside: the ``wall.*`` columns).
"""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.scenario.source import parse_override
from rehabkit.sweep.execute import RunTimeoutError, execute
from rehabkit.sweep.grid import RunSpec, expand, parse_grid
from rehabkit.sweep.store import RunStore
from rehabkit.sweep.tables import aggregate, flat_rows, format_table, write_csv, write_parquet

RUNS = "runs"  # the sweep folder's subfolder of kept runs, one per run id


@dataclass
class SweepResult:
    """A finished sweep: its rows (grid order), the aggregate per grid point, and what this call ran."""

    records: list[dict[str, Any]]
    aggregate: list[dict[str, Any]]
    keys: list[str]
    metrics: list[str]
    executed: int
    skipped: int
    out_dir: Path
    wall_s: float
    keeps_runs: bool = False  # each run's outputs under runs/<run id>/

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.records if r["error"] is not None]

    def table(self) -> str:
        return format_table(self.aggregate, self.keys, self.metrics)


def run_sweep(scenario: str | Path, grid: Mapping[str, list[Any]] | Iterable[str] | None = None,
              seeds: int | None = None, out_dir: str | Path | None = None, *, address: str | None = None,
              workers: int | None = None, serial: bool = False, timeout_s: float | None = None,
              metrics: Iterable[str] = (), progress: bool = False, overrides: Iterable[str] = (),
              keep_runs: bool | None = None) -> SweepResult:
    """Run ``scenario`` over ``grid`` × ``seeds`` (default: its ``sweep:`` block; arguments add to it).

    Args:
        grid: key path → values, or ``--grid`` strings (``"planner.type=a,b"``).
        seeds: runs per grid point (scenario seeds 0..seeds-1).
        out_dir: the sweep's directory (default ``out/sweep_<scenario name>``); finished runs there are skipped.
        address: an existing Ray cluster (``ray://host:10001``); default: the Ray this process runs
            (:func:`start_ray`), or a local one started for the sweep.
        workers: CPUs of the local Ray (default: all).
        serial: run in this process, one after the other (no Ray).
        timeout_s: a run taking longer is stopped and recorded as failed.
        overrides: ``--set`` strings every run has (under the grid's values).
        keep_runs: each run's outputs in ``runs/<run id>/`` (default: the ``sweep:`` block's ``keep_runs``).
    """
    t0 = time.perf_counter()
    path = Path(scenario).resolve()
    fixed = {".".join(keys): value for keys, value in map(parse_override, overrides)}
    base = load_scenario(path, fixed).model  # the scenario itself must be valid (located errors if not)
    spec = base.sweep
    keep = keep_runs if keep_runs is not None else bool(spec and spec.keep_runs)
    merged: dict[str, list[Any]] = dict(spec.grid) if spec else {}
    merged.update(parse_grid(grid) if grid is not None and not isinstance(grid, Mapping) else (grid or {}))
    seeds = seeds or (spec.seeds if spec else 1)
    timeout_s = timeout_s or (spec.timeout_s if spec else 600.0)
    shown = list(dict.fromkeys([*(spec.metrics if spec else []), *metrics, *base.expect]))
    for point in _points(merged):  # every grid value must make a valid scenario: located errors before any run
        load_scenario(path, fixed, grid=point)
    specs = expand(path, merged, seeds, fixed)
    out = Path(out_dir) if out_dir is not None else Path("out") / f"sweep_{path.stem}"
    store = RunStore(out)
    store.describe({"scenario": str(path), "grid": merged, "seeds": seeds, "timeout_s": timeout_s,
                    "runs": len(specs), **({"set": fixed} if fixed else {}), **({"keep_runs": True} if keep else {})})
    rows = store.done(specs)
    todo = [s for s in specs if s.run_id not in rows]
    bar = tqdm(total=len(specs), initial=len(specs) - len(todo), unit="run", disable=not progress)

    def record(s: RunSpec, row: dict[str, Any]) -> None:
        if keep:
            row["run_dir"] = f"{RUNS}/{s.run_id}"
        store.save(s, row)
        rows[s.run_id] = row
        bar.update(1)

    def run_dir(s: RunSpec) -> str | None:
        return str((out / RUNS / s.run_id).resolve()) if keep else None

    if serial:
        for s in todo:
            row = execute(str(path), s.overrides, timeout_s, run_dir(s))
            record(s, row)
            if row.get("ended", {}).get("how") == "interrupted":  # Ctrl-C, SIGTERM: the run recorded, the sweep stops
                from rehabkit.core.run.signals import Terminated

                raise Terminated() if row["ended"].get("signal") == "SIGTERM" else KeyboardInterrupt()
    elif todo:
        _on_ray(todo, str(path), timeout_s, address, workers, record, run_dir)
    bar.close()
    records = flat_rows(specs, rows)
    keys = list(merged)
    agg = aggregate(records, keys, shown)
    write_parquet(out / "results.parquet", records)
    write_csv(out / "aggregate.csv", agg)
    return SweepResult(records, agg, keys, shown, len(todo), len(specs) - len(todo), out, time.perf_counter() - t0,
                       keep)


def _points(grid: Mapping[str, list[Any]]) -> list[dict[str, Any]]:
    """One override set per value of each key (enough to check every value once)."""
    return [{key: value} for key, values in grid.items() for value in values]


def start_ray(address: str | None = None, workers: int | None = None) -> None:
    """Connect to the Ray cluster at ``address``, or start a local one with ``workers`` CPUs (default: all).

    A sweep started while Ray runs uses it and leaves it running (a notebook's several sweeps, or a test
    module's, pay Ray's start-up of several seconds once); otherwise the sweep starts it and stops it after.
    """
    import ray

    if address:
        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
    else:
        ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False, log_to_driver=False,
                 logging_level=logging.WARNING, object_store_memory=256 * 1024**2)


def _on_ray(todo: list[RunSpec], path: str, timeout_s: float, address: str | None, workers: int | None,
            record: Callable[[RunSpec, dict[str, Any]], None], run_dir: Callable[[RunSpec], str | None]) -> None:
    import ray

    started = not ray.is_initialized()
    if started:
        start_ray(address, workers)
    try:
        slots = max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(num_cpus=1, max_retries=0)(execute)
        queue, running = deque(todo), {}
        try:
            _drain(queue, running, slots, remote, path, timeout_s, record, run_dir)
        except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM: the runs under way recorded as cut short (run again on
            said = getattr(exc, "signal", "SIGINT")  # resuming), the workers stopped with Ray, the sweep stops
            for ref, (s, t_start) in running.items():
                ray.cancel(ref, force=True)
                record(s, _interrupted(said, t_start))
            raise
    finally:
        if started:
            ray.shutdown()


def _drain(queue: deque, running: dict, slots: int, remote, path: str, timeout_s: float,
           record: Callable[[RunSpec, dict[str, Any]], None], run_dir: Callable[[RunSpec], str | None]) -> None:
    """Keep ``slots`` runs going on Ray until ``queue`` is empty, recording each as it ends (a failed worker, a run
    past ``timeout_s``: recorded as failed)."""
    import ray

    while queue or running:
        while queue and len(running) < slots:
            s = queue.popleft()
            running[remote.remote(path, s.overrides, None, run_dir(s))] = (s, time.monotonic())
        done, _ = ray.wait(list(running), num_returns=1, timeout=0.2)
        for ref in done:
            s, t_start = running.pop(ref)
            try:
                row = ray.get(ref)
            except Exception as exc:  # noqa: BLE001 (the worker died, the task failed: recorded)
                row = _failed(f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1][:500]}", t_start,
                              type(exc).__name__)
            record(s, row)
        now = time.monotonic()
        for ref, (s, t_start) in list(running.items()):
            if now - t_start > timeout_s:
                ray.cancel(ref, force=True)
                del running[ref]
                record(s, _failed(f"RunTimeoutError: timeout: still running after {timeout_s:g} s", t_start,
                                  RunTimeoutError.__name__))


def _interrupted(signal: str, t_start: float) -> dict[str, Any]:
    """A run under way on Ray when the sweep was stopped: recorded as cut short (the store runs it again)."""
    return {**_failed(f"interrupted ({signal}): the sweep was stopped while it ran", t_start),
            "ended": {"how": "interrupted", "signal": signal, "reason": "the sweep was stopped while it ran"}}


def _failed(error: str, t_start: float, error_type: str | None = None) -> dict[str, Any]:
    """A run that left no row of its own (its worker died, it timed out on Ray, the sweep was stopped): ``error``
    in words, ``error_type`` the error's class name where there was one."""
    return {"error": error, "error_type": error_type, "error_missing": None, "passed": False, "metrics": {},
            "expectations": {}, "wall_time_s": time.monotonic() - t_start}
