"""Counterfactual replay: a recorded session run again with another controller or planner.

Every run directory holds ``scenario.yaml``, the scenario exactly as it ran (its
``extends:`` merged, the patient profile inlined, ``--set`` applied). A replay loads
that snapshot, applies new overrides, and runs it with the same seed: the same
target timeline, the same patient parameters and noise (the simulated patient
draws from a stream of its own), the same sensor noise. The summary's ``inputs``
section fingerprints those inputs so the comparison can say whether they matched.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rehabkit.core.plugins.registry import PluginRegistry
from rehabkit.core.results.summary import RunResult
from rehabkit.core.run.runner import SNAPSHOT, Runner
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.scenario.loader import load_scenario


@dataclass
class Replay:
    """An original run's summary beside its counterfactual."""

    original: dict[str, Any]
    result: RunResult
    same_inputs: dict[str, bool]
    changes: list[str] = field(default_factory=list)  # the overrides the replay ran with (--set)

    def rows(self) -> list[tuple[str, Any, Any]]:
        """(metric, original, replay) for the outcome measures either run has (as their summaries describe them)."""
        a, b = self.original["metrics"], self.result.summary["metrics"]
        info = {**self.original.get("metric_info", {}), **self.result.summary.get("metric_info", {})}
        keys = [k for k in dict.fromkeys([*a, *b]) if info.get(k, {}).get("outcome")]
        return [(k, a.get(k), b.get(k)) for k in keys]

    def table(self) -> str:
        """The metrics side by side, with which plugins each run used."""
        def label(s: dict) -> str:
            if "label" in s:  # a recorded session, not a run
                return s["label"]
            p = s["plugins"]
            return f"{p['controller']['type']} / {p['planner']['type']}"

        def fmt(v: Any) -> str:
            return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4g}"

        head = ("metric", label(self.original), label(self.result.summary))
        rows = [head] + [(k, fmt(x), fmt(y)) for k, x, y in self.rows()]
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
                 for r in rows]
        lines.insert(1, "  ".join("-" * w for w in widths))
        same = ", ".join(f"{k} {'same' if v else 'DIFFERENT'}" for k, v in self.same_inputs.items())
        changed = f"\nreplayed with: {', '.join(self.changes)}" if self.changes else ""
        return "\n".join(lines) + changed + (f"\ninputs: {same}" if same else "")


def overrides_label(overrides: Iterable[str]) -> str:
    """A folder-name label of the overrides' values (``again`` for none)."""
    text = "_".join(o.split("=", 1)[-1] for o in overrides) or "again"
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text)[:60]


def replay(run_dir: str | Path, overrides: Iterable[str] = (), out_dir: str | Path | None = None,
           registry: PluginRegistry | None = None, progress: bool = False) -> Replay:
    """Run the session recorded in ``run_dir`` again with ``overrides``; outputs in ``out_dir``
    (default ``run_dir/replay-<values>``).

    Raises:
        ScenarioError: ``run_dir`` holds no recorded run, or the overrides are invalid.
    """
    run_dir = Path(run_dir)
    snap, summ = run_dir / SNAPSHOT, run_dir / "summary.json"
    if not (snap.exists() and summ.exists()):
        raise ScenarioError([Diagnostic(Mark(str(run_dir), 0, 0), "", f"not a run directory: it needs {SNAPSHOT} "
                                                                         "and summary.json (written by rehabkit run)")])
    original = json.loads(summ.read_text())
    overrides = list(overrides)
    loaded = load_scenario(snap, overrides, registry, origin=Path(original["scenario"]))
    out = Path(out_dir) if out_dir is not None else run_dir / f"replay-{overrides_label(overrides)}"
    result = Runner(loaded, registry, out, progress=progress).run()
    a, b = original.get("inputs", {}), result.summary["inputs"]
    same = {key: a.get(key) == b.get(key) for key in b}
    return Replay(original, result, same, overrides)
