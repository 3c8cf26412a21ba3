"""The public Python API: load and run scenarios, and sweeps of them."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rehabkit.core.plugins.registry import PluginRegistry
from rehabkit.core.run.runner import Runner, RunResult
from rehabkit.core.scenario.loader import LoadedScenario, load_scenario

if TYPE_CHECKING:
    from rehabkit.sweep.engine import SweepResult, run_sweep


def run_scenario(
    path: str | Path,
    overrides: Iterable[str] | Mapping[str, Any] = (),
    out_dir: str | Path | None = None,
    *,
    registry: PluginRegistry | None = None,
    spawn: bool = False,
    progress: bool = False,
) -> RunResult:
    """Load, validate and run a scenario.

    Args:
        path: Scenario YAML.
        overrides: ``["planner.segment_durations=[1,1,1,1]"]`` or ``{"planner.segment_durations": [1, 1, 1, 1]}``.
        out_dir: Where to write ``run.rrd`` and ``summary.json``; ``None`` writes nothing.
        registry: Plugins to use (default: the installed ones).
        spawn: Also stream the log to a Rerun viewer.
        progress: Show a progress bar on long runs.

    Raises:
        ScenarioError: the file is invalid (every problem, located).
        SetupError: the plugins can't be put together as configured.
    """
    loaded: LoadedScenario = load_scenario(path, overrides, registry)
    out = Path(out_dir) if out_dir is not None else None
    return Runner(loaded, registry, out, spawn=spawn, progress=progress).run()


def __getattr__(name: str):
    # sweeps (Ray, Parquet, a progress bar) load when a sweep is asked for, not with every run
    if name in ("run_sweep", "SweepResult"):
        from rehabkit.sweep import engine

        return getattr(engine, name)
    raise AttributeError(f"module 'rehabkit.api' has no attribute {name!r}")


__all__ = ["LoadedScenario", "RunResult", "SweepResult", "load_scenario", "run_scenario", "run_sweep"]
