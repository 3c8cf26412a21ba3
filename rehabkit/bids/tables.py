"""The dataset's files as BIDS wants them, each written whole or not at all (a temporary file beside it, then
renamed): tab-separated tables with a header (``n/a`` for nothing), JSON sidecars, and the motion data — no header,
one column per channel, numbers only — checked once written, since the validators do not: every value a number (or
``n/a``), as many columns as channels, as many rows as samples, each equal to the trace to the decimals printed.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from rehabkit.core.io import atomic_write_bytes


class OutputError(RuntimeError):
    """A file the exporter wrote that is not what it meant to write (its own check failed): nothing is kept."""


def _cell(v: Any) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if isinstance(v, float):
        return f"{v:.10g}"
    return str(v)


def tsv_text(columns: list[str], rows: list[dict[str, Any]]) -> str:
    lines = ["\t".join(columns)] + ["\t".join(_cell(r.get(c)) for c in columns) for r in rows]
    return "\n".join(lines) + "\n"


def read_tsv(path: Path) -> list[dict[str, str]]:
    """A table's rows (column → text); none where the file does not exist."""
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f, delimiter="\t"))


def write_file(path: Path, data: bytes | str) -> None:
    """``data`` in a temporary file beside ``path``, synced, then renamed onto it."""
    atomic_write_bytes(path, data.encode() if isinstance(data, str) else data)


def write_json(path: Path, data: dict) -> None:
    write_file(path, json.dumps(data, indent=2, ensure_ascii=False) + "\n")


def write_tsv(path: Path, columns: list[str], rows: list[dict[str, Any]]) -> None:
    write_file(path, tsv_text(columns, rows))


def motion_bytes(data: np.ndarray, decimals: list[int]) -> bytes:
    """The motion table's text: no header, tab-separated, each column ``data``'s rounded to its ``decimals``, ``n/a``
    for a missing value."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    cols = [pc.fill_null(pc.cast(pa.array(np.round(data[:, i], d) + 0.0, from_pandas=True), pa.string()), "n/a")
            for i, d in enumerate(decimals)]  # (+0.0: no "-0")
    table = pa.table(cols, names=[f"c{i}" for i in range(len(cols))])
    out = io.BytesIO()
    pcsv.write_csv(table, out, pcsv.WriteOptions(include_header=False, delimiter="\t", quoting_style="none"))
    return out.getvalue()


def read_motion(path: Path, columns: int) -> list[np.ndarray]:
    """A motion table read back as numbers, a column at a time (``n/a`` as NaN). Raises :class:`OutputError` where a
    value is not a number or a row has another count of columns."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    names = [f"c{i}" for i in range(columns)]
    try:
        table = pcsv.read_csv(path, pcsv.ReadOptions(column_names=names),
                              pcsv.ParseOptions(delimiter="\t", quote_char=False),
                              pcsv.ConvertOptions(null_values=["n/a"], strings_can_be_null=True,
                                                  column_types={n: pa.float64() for n in names}))
    except pa.ArrowInvalid as exc:  # a value that is not a number; a row with more or fewer columns
        raise OutputError(f"{path}: {exc}") from exc
    return [table.column(n).to_numpy(zero_copy_only=False) for n in names]


def write_motion(path: Path, data: np.ndarray, decimals: list[int]) -> float:
    """``data`` (samples × channels) written as a motion table, then read back and checked: a number (or ``n/a``
    where the value is missing) in each of as many columns as channels, a row per sample, each the value to half a
    unit of its last decimal. Returns the largest difference found [in each column's unit]."""
    write_file(path, motion_bytes(data, decimals))
    back = read_motion(path, data.shape[1])
    largest = 0.0
    for j, (col, d) in enumerate(zip(back, decimals)):
        if len(col) != data.shape[0]:
            raise OutputError(f"{path}: {len(col)} rows written for {data.shape[0]} samples")
        meant = data[:, j]
        missing = ~np.isfinite(meant)
        if not np.array_equal(missing, ~np.isfinite(col)):
            raise OutputError(f"{path}: column {j + 1}: n/a where a value was meant, or a value where n/a was")
        diff = np.abs(np.where(missing, 0.0, col - meant))
        bound = 0.5 * 10.0 ** -d * (1 + 1e-9) + 1e-12 * np.abs(np.where(missing, 0.0, meant))
        if (diff > bound).any():
            i = int(np.argmax(diff - bound))
            raise OutputError(f"{path}: row {i + 1}, column {j + 1} reads {col[i]!r} for {meant[i]!r}")
        largest = max(largest, float(diff.max()) if diff.size else 0.0)
    return largest
