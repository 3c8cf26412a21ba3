"""A sweep's directory: one file per finished run (so a killed sweep resumes), then the tables.

    DIR/sweep.json          what the sweep is (scenario, grid, seeds)
    DIR/runs/<run id>.json  one row per finished run, written whole (temp file, then rename); a run Ctrl-C or
                            SIGTERM cut short is recorded so ("ended") and run again when the sweep resumes
    DIR/results.parquet     all rows, in grid order (columnar: grid keys, seed, passed, error,
                            error_type (the error's class name), error_missing (the capabilities a plugin
                            needed that the robot or backend lacks, where that is why), wall_time_s,
                            metric.<name>, wall.<name> for wall-clock metrics, expect.<metric>)
    DIR/aggregate.csv       per grid point: runs, failures, share passed, mean/std of each metric
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rehabkit.core.io import atomic_write_json
from rehabkit.sweep.grid import RunSpec


class RunStore:
    """Finished runs of a sweep, on disk."""

    def __init__(self, directory: Path):
        self.dir = Path(directory)
        self.runs = self.dir / "runs"
        self.runs.mkdir(parents=True, exist_ok=True)

    def done(self, specs: list[RunSpec]) -> dict[str, dict[str, Any]]:
        """Rows already recorded for these runs (by id)."""
        out = {}
        for spec in specs:
            f = self.runs / f"{spec.run_id}.json"
            if f.exists():
                try:
                    row = json.loads(f.read_text())
                except (OSError, json.JSONDecodeError):  # not written whole (cannot happen with rename): rerun
                    continue
                if row.get("ended", {}).get("how") != "interrupted":  # (cut short by Ctrl-C, SIGTERM: run again)
                    out[spec.run_id] = row
        return out

    def save(self, spec: RunSpec, row: dict[str, Any]) -> None:
        atomic_write_json(self.runs / f"{spec.run_id}.json", row)

    def describe(self, info: dict[str, Any]) -> None:
        atomic_write_json(self.dir / "sweep.json", info)
