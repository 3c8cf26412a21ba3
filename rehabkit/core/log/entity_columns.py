"""Many entities' time series gathered between sends and sent to a recording as one Arrow record batch per time column.

``send_columns`` costs ~0.15-0.3 ms of Python a call whatever its length, and a run's log sends some 30 entities at
each flush (each joint's measured and reference position, the shared speed/effort/error panels, every body's pose, the
hand). Gathered here, they go in one :meth:`rerun.RecordingStream.send_record_batch` a time column: Rerun splits the
batch into one chunk per entity (each column names its entity in its ``rerun:entity_path`` field metadata), and the
recording holds the same chunks as with a call per entity.

The columns' Rerun types — archetype, component, component type and Arrow datatype — come from the SDK's public
descriptors and component batches (``rr.Scalars.descriptor_scalars()``, ``rr.components.ScalarBatch``), so they follow
the installed rerun-sdk rather than being written out here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr

from rehabkit.core.log.buffers import TIMELINE


def _meta(descriptor: Any, path: str) -> dict[bytes, bytes]:
    """A component column's field metadata: its entity, archetype, component and component type (Rerun's sorbet
    keys, as ``Chunk.to_record_batch`` writes them)."""
    return {b"rerun:kind": b"data", b"rerun:entity_path": path.encode(),
            b"rerun:archetype": descriptor.archetype.encode(), b"rerun:component": descriptor.component.encode(),
            b"rerun:component_type": descriptor.component_type.encode()}


def _per_row(flat: pa.Array, n: int, width: int) -> pa.Array:
    """``n`` rows of ``width`` instances each, as the list array a component column holds."""
    return pa.ListArray.from_arrays(pa.array(np.arange(0, (n + 1) * width, width, dtype=np.int32)), flat)


class EntityColumns:
    """Component columns of many entities, grouped by their time column until :meth:`take`."""

    def __init__(self) -> None:
        # a time column (by the identity of the array the caller passed) -> (its times, [(entity, field, array)])
        self._groups: dict[int, tuple[np.ndarray, list[tuple[str, pa.Field, pa.Array]]]] = {}

    def __len__(self) -> int:
        return sum(len(columns) for _, columns in self._groups.values())

    def _add(self, t: np.ndarray, path: str, descriptor: Any, column: pa.Array) -> None:
        group = self._groups.get(id(t))
        if group is None:  # (the array kept with its group: its id is not reused before the take)
            group = self._groups[id(t)] = (t, [])
        field = pa.field(f"{path}:{descriptor.component}", column.type, metadata=_meta(descriptor, path))
        group[1].append((path, field, column))

    def scalars(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """A :class:`rr.Scalars` series: one value a row (``values`` of shape ``(n,)``) or several (``(n, k)``)."""
        values = np.asarray(values, float)
        width = 1 if values.ndim == 1 else values.shape[1]
        flat = rr.components.ScalarBatch(values.reshape(-1)).as_arrow_array()
        self._add(t, path, rr.Scalars.descriptor_scalars(), _per_row(flat, len(t), width))

    def transforms(self, path: str, t: np.ndarray, translation: np.ndarray, quat_xyzw: np.ndarray) -> None:
        """A :class:`rr.Transform3D` a row: its translation and its rotation (a quaternion, x y z w)."""
        n = len(t)
        self._add(t, path, rr.Transform3D.descriptor_translation(),
                  _per_row(rr.components.Translation3DBatch(translation).as_arrow_array(), n, 1))
        self._add(t, path, rr.Transform3D.descriptor_quaternion(),
                  _per_row(rr.components.RotationQuatBatch(quat_xyzw).as_arrow_array(), n, 1))

    def points(self, path: str, t: np.ndarray, positions: np.ndarray) -> None:
        """A :class:`rr.Points3D` of one point a row."""
        flat = rr.components.Position3DBatch(np.asarray(positions, float).reshape(-1, 3)).as_arrow_array()
        self._add(t, path, rr.Points3D.descriptor_positions(), _per_row(flat, len(t), 1))

    def take(self, per_entity: bool = False) -> list[pa.RecordBatch]:
        """The gathered columns as record batches — one a time column, or one an entity with ``per_entity`` (a
        real-time run sends one a tick) — and none left gathered."""
        groups, self._groups = self._groups, {}
        batches = []
        for t, columns in groups.values():
            time_field = pa.field(TIMELINE, pa.duration("ns"),
                                  metadata={b"rerun:kind": b"index", b"rerun:index_name": TIMELINE.encode()})
            times = rr.TimeColumn(TIMELINE, duration=np.asarray(t, float)).as_arrow_array()
            parts = [columns] if not per_entity else list(_by_entity(columns).values())
            for part in parts:
                batches.append(pa.RecordBatch.from_arrays([times] + [c for _, _, c in part],
                                                          schema=pa.schema([time_field] + [f for _, f, _ in part])))
        return batches


def _by_entity(columns: list[tuple[str, pa.Field, pa.Array]]) -> dict[str, list[tuple[str, pa.Field, pa.Array]]]:
    out: dict[str, list] = {}
    for column in columns:
        out.setdefault(column[0], []).append(column)
    return out
