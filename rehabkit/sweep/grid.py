"""What a sweep runs: the grid's combinations × seeds, each with a stable id."""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from rehabkit.core.io import load_yaml


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: the scenario with these overrides and this seed."""

    point: tuple[tuple[str, Any], ...]  # grid key → value, in the grid's key order
    seed: int
    run_id: str
    fixed: tuple[tuple[str, Any], ...] = ()  # settings every run of the sweep has (--set), under the grid's

    @property
    def overrides(self) -> dict[str, Any]:
        return {**dict(self.fixed), **dict(self.point), "seed": self.seed}


def parse_grid(items: Iterable[str]) -> dict[str, list[Any]]:
    """``["planner.type=voxel-astar,voxel-hill", "controller.kp=[1,2],[3,4]"]`` → key → values (YAML each)."""
    grid: dict[str, list[Any]] = {}
    for text in items:
        key, sep, raw = text.partition("=")
        if not sep or not key.strip() or not raw.strip():
            raise ValueError(f"--grid '{text}': expected key.path=value1,value2,...")
        try:
            values = load_yaml(f"[{raw}]")
        except yaml.YAMLError as exc:
            raise ValueError(f"--grid '{text}': the values are not valid YAML ({exc})") from None
        grid[key.strip()] = values
    return grid


def scenario_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def expand(path: Path, grid: Mapping[str, list[Any]], seeds: int, fixed: Mapping[str, Any] | None = None
           ) -> list[RunSpec]:
    """Every combination of the grid's values (first key slowest) × seeds 0..seeds-1, each with the ``fixed``
    settings (a run's id covers them: a sweep resumed with other settings runs again)."""
    if "seed" in grid:
        raise ValueError("'seed' is set by the sweep's seeds, not by the grid")
    for key, values in grid.items():
        if not values:
            raise ValueError(f"grid key '{key}' has no values")
    digest = scenario_digest(path)
    keys = list(grid)
    same = tuple(sorted((fixed or {}).items()))
    runs = []
    for combo in itertools.product(*(grid[k] for k in keys)):
        point = tuple(zip(keys, combo))
        for seed in range(seeds):
            what = {"scenario": digest, "point": point, "seed": seed, **({"fixed": same} if same else {})}
            ident = json.dumps(what, sort_keys=True, default=str)
            runs.append(RunSpec(point, seed, hashlib.sha256(ident.encode()).hexdigest()[:16], same))
    return runs


def point_label(point: tuple[tuple[str, Any], ...]) -> dict[str, str]:
    """Grid values as text, one column per key: strings as they are; a whole plugin section by its type and its
    scalar settings (``joint-pd kp=300``), with a short digest of the rest where anything was left out or the
    text grew long (so distinct values keep distinct labels); anything else as JSON."""
    return {k: _label(v) for k, v in point}


def _label(value: Any) -> str:
    if isinstance(value, str):
        return value
    if not isinstance(value, dict):
        return json.dumps(value)
    parts = [str(value["type"])] if "type" in value else []
    scalar = {k: v for k, v in value.items() if k != "type" and not isinstance(v, (dict, list))}
    parts += [f"{k}={v}" for k, v in scalar.items()]
    text = " ".join(parts)
    if len(scalar) + ("type" in value) < len(value) or len(text) > 48 or not text:
        digest = hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()[:6]
        text = f"{text[:40]} #{digest}".strip()
    return text
