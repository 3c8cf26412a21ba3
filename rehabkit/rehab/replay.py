"""Counterfactual replay: a recorded session run again with another controller or planner.

Every run directory holds ``scenario.yaml``, the scenario exactly as it ran (its
``extends:`` merged, the patient profile inlined, ``--set`` applied). A replay loads
that snapshot, applies new overrides, and runs it with the same seed: the same
target timeline, the same patient parameters and noise (the simulated patient
draws from a stream of its own), the same sensor noise. The summary's ``inputs``
section fingerprints those inputs so the comparison can say whether they matched.

A replay *forked* at a time (``fork_at``) keeps the recorded session up to then: the original scenario runs to that
step, its session is snapshotted (:mod:`rehabkit.core.run.snapshot`) and put into the replay's, which goes on with the
new settings from there — the same person in the same state, the plan under way the original's, the trace before the
fork the original's bit for bit. A plugin whose settings changed starts afresh at the fork; the new settings'
planner plans at the next event. The replay's recording holds the run from the fork on.
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
from rehabkit.core.run.loop import run_loop
from rehabkit.core.run.runner import SNAPSHOT, Runner
from rehabkit.core.run.snapshot import SessionSnapshot, restore, snapshot
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.scenario.loader import load_scenario


@dataclass
class Replay:
    """An original run's summary beside its counterfactual."""

    original: dict[str, Any]
    result: RunResult
    same_inputs: dict[str, bool]
    changes: list[str] = field(default_factory=list)  # the overrides the replay ran with (--set)
    fork: dict[str, Any] | None = None  # forked: at what time and step, and which plugins started afresh

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
           registry: PluginRegistry | None = None, progress: bool = False, fork_at: float | None = None) -> Replay:
    """Run the session recorded in ``run_dir`` again with ``overrides``; outputs in ``out_dir``
    (default ``run_dir/replay-<values>``, ``replay-<values>-at-<t>s`` forked). ``fork_at``: keep the recorded session
    up to this time [s] and go on from there with the overrides (the module docstring).

    Raises:
        ScenarioError: ``run_dir`` holds no recorded run, the overrides are invalid, or the fork can't be made
            (a time outside the run, a robot's backend, another scene or duration).
    """
    run_dir = Path(run_dir)
    snap, summ = run_dir / SNAPSHOT, run_dir / "summary.json"
    if not (snap.exists() and summ.exists()):
        raise ScenarioError([Diagnostic(Mark(str(run_dir), 0, 0), "", f"not a run directory: it needs {SNAPSHOT} "
                                                                         "and summary.json (written by rehabkit run)")])
    original = json.loads(summ.read_text())
    overrides = list(overrides)
    loaded = load_scenario(snap, overrides, registry, origin=Path(original["scenario"]))
    label = overrides_label(overrides) + (f"-at-{fork_at:g}s" if fork_at is not None else "")
    out = Path(out_dir) if out_dir is not None else run_dir / f"replay-{label}"
    runner = Runner(loaded, registry, out, progress=progress)
    fork, prepare = None, None
    if fork_at is not None:
        taken = _recorded_until(snap, fork_at, registry, original)
        fork = {"t": fork_at, "step": taken.k}

        def prepare(session) -> None:
            fork["fresh"] = _put(session, taken, snap)
    result = runner.run(prepare)
    a, b = original.get("inputs", {}), result.summary["inputs"]
    same = {key: a.get(key) == b.get(key) for key in b}
    return Replay(original, result, same, overrides, fork)


def _recorded_until(path: Path, t: float, registry: PluginRegistry | None, original: dict) -> SessionSnapshot:
    """The recorded session standing at time ``t``: its scenario as it ran, run again to there (nothing written)."""
    loaded = load_scenario(path, (), registry, origin=Path(original["scenario"]))
    dt = 1.0 / loaded.model.rates.control_hz
    k = int(round(t / dt))
    if not 0 < k < round(loaded.model.duration / dt):
        raise _fork_error(path, f"--fork-at {t:g} s is outside the run (0 … {loaded.model.duration:g} s)")
    runner = Runner(loaded, registry)
    session = runner.start()
    try:
        run_loop(session, k_to=k)
        if session.loop.k < k:
            raise _fork_error(path, f"the recorded session ended at {session.loop.k * dt:g} s, before --fork-at "
                                    f"{t:g} s")
        return snapshot(session)
    except TypeError as exc:  # (NotRestorableError: a robot's backend)
        raise _fork_error(path, str(exc)) from None
    finally:
        session.setup.backend.close()


def _put(session, snap: SessionSnapshot, snap_path: Path) -> list[str]:
    try:
        return restore(session, snap)
    except ValueError as exc:  # (SnapshotMismatchError: another scene or duration)
        raise _fork_error(snap_path, f"can't fork into the replay: {exc}") from None


def _fork_error(path: Path, text: str) -> ScenarioError:
    return ScenarioError([Diagnostic(Mark(str(path), 0, 0), "", text)])
