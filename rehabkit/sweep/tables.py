"""A sweep's rows as a columnar table (Parquet), and the per-grid-point aggregate."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from rehabkit.core.io import atomic_write_text
from rehabkit.sweep.grid import RunSpec, point_label


def flat_rows(specs: list[RunSpec], rows: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """One flat record per run, in the sweep's order: grid values, seed, outcome, metric.*, expect.*."""
    out = []
    numeric = _numeric_keys(specs)
    for spec in specs:
        row = rows[spec.run_id]
        label = {**point_label(spec.point), **{k: v for k, v in spec.point if k in numeric}}
        rec: dict[str, Any] = {"run_id": spec.run_id, **label, "seed": spec.seed,
                               "passed": bool(row["passed"]), "error": row["error"],
                               # the error as fields (a row stored before they were: none)
                               "error_type": row.get("error_type"), "error_missing": row.get("error_missing"),
                               "wall_time_s": float(row["wall_time_s"]),
                               **({"run_dir": row["run_dir"]} if row.get("run_dir") else {})}
        wall = set(row.get("wall_clock", ()))  # wall-clock figures: columns of their own, not compared
        rec.update({f"{'wall' if k in wall else 'metric'}.{k}": v for k, v in sorted(row["metrics"].items())})
        rec.update({f"expect.{k}": v for k, v in sorted(row["expectations"].items())})
        out.append(rec)
    return out


def _numeric_keys(specs: list[RunSpec]) -> set[str]:
    """Grid keys whose every value is a number: kept as numbers (a column to plot against), the rest as text."""
    values: dict[str, list[Any]] = {}
    for spec in specs:
        for k, v in spec.point:
            values.setdefault(k, []).append(v)
    return {k for k, vs in values.items()
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vs)}


def reproducible(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records without their wall-clock figures: what any two runs of the same sweep agree on."""
    return [{k: v for k, v in r.items() if k != "wall_time_s" and not k.startswith("wall.")} for r in records]


def write_parquet(path: Path, records: list[dict[str, Any]]) -> None:
    """All records in one Parquet file (columns: the union of the records' keys; missing values null)."""
    columns: dict[str, None] = {}
    for rec in records:
        columns.update(dict.fromkeys(rec))
    table = pa.Table.from_pylist([{c: rec.get(c) for c in columns} for rec in records])
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    tmp.replace(path)


def read_parquet(path: Path) -> list[dict[str, Any]]:
    return pq.read_table(path).to_pylist()


def aggregate(records: list[dict[str, Any]], keys: list[str], metrics: list[str]) -> list[dict[str, Any]]:
    """Per grid point (in first-seen order): runs, errors, share passed, and mean, std (the sample's, across seeds:
    none for one run) and n of ``metrics``."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for rec in records:
        groups.setdefault(tuple(rec[k] for k in keys), []).append(rec)
    out = []
    for point, recs in groups.items():
        row: dict[str, Any] = dict(zip(keys, point))
        row.update(runs=len(recs), errors=sum(r["error"] is not None for r in recs),
                   passed=float(np.mean([r["passed"] for r in recs])))
        for m in metrics:
            got = (r.get(f"metric.{m}", r.get(f"wall.{m}")) for r in recs)
            vals = np.array([v for v in got if v is not None], float)
            row[f"{m}.mean"] = float(vals.mean()) if len(vals) else math.nan
            row[f"{m}.std"] = float(vals.std(ddof=1)) if len(vals) > 1 else math.nan  # (across seeds: none of one)
            row[f"{m}.n"] = len(vals)
        out.append(row)
    return out


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    buf = io.StringIO()
    if rows:
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    atomic_write_text(path, buf.getvalue())


def format_table(rows: list[dict[str, Any]], keys: list[str], metrics: list[str]) -> str:
    """The aggregate for people: one line per grid point, metrics as mean ± std (n)."""
    head = [*keys, "runs", "errors", "passed", *metrics]
    lines = [head]
    for r in rows:
        cells = [str(r[k]) for k in keys] + [str(r["runs"]), str(r["errors"]), f"{r['passed']:.1%}"]
        cells += [f"{r[f'{m}.mean']:.4g}" + (f" ± {r[f'{m}.std']:.2g}" if r[f"{m}.n"] > 1 else "") + f" ({r[f'{m}.n']})"
                  for m in metrics]
        lines.append(cells)
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in lines)
