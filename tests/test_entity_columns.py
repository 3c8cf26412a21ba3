"""The log's record batches of many entities hold what a ``send_columns`` call per entity holds (read back by
Rerun's own reader): same entities, components, component types, times and values."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import RrdReader

from rehabkit.core.log.buffers import TIMELINE
from rehabkit.core.log.entity_columns import EntityColumns


def _contents(path) -> dict:
    """entity → component → (its component type, [(time ns, value)]) over every chunk of a recording."""
    out: dict = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if TIMELINE not in batch.schema.names:
            continue
        times = batch.column(TIMELINE).cast(pa.int64()).to_pylist()
        for i, field in enumerate(batch.schema):
            meta = field.metadata or {}
            if meta.get(b"rerun:kind") != b"data":
                continue
            kind, rows = out.setdefault(str(chunk.entity_path), {}).setdefault(
                meta[b"rerun:component"].decode(), (meta[b"rerun:component_type"].decode(), []))
            rows.extend(zip(times, batch.column(i).to_pylist(), strict=True))
    return {e: {c: (kind, sorted(rows)) for c, (kind, rows) in comps.items()} for e, comps in out.items()}


def test_one_batch_of_many_entities_records_what_a_call_per_entity_records(tmp_path):
    rng = np.random.default_rng(7)
    t, t_other = np.arange(40) * 0.01, np.arange(5) * 0.2 + 0.005
    joint, wide, limits = rng.normal(size=40), rng.normal(size=(40, 3)), np.array([[-1.0, 1.0], [-1.0, 1.0]])
    translation, quat = rng.normal(size=(40, 3)), rng.normal(size=(40, 4))
    hand = rng.normal(size=(40, 3))

    by_call = rr.RecordingStream("rehabkit-test")
    by_call.save(tmp_path / "calls.rrd")
    times = [rr.TimeColumn(TIMELINE, duration=t)]
    by_call.send_columns("joints/a/measured_deg", indexes=times, columns=rr.Scalars.columns(scalars=joint))
    by_call.send_columns("joint_velocity_deg_s", indexes=times, columns=rr.Scalars.columns(scalars=wide))
    by_call.send_columns("joints/a/limits_deg", indexes=[rr.TimeColumn(TIMELINE, duration=t_other[:2])],
                         columns=rr.Scalars.columns(scalars=limits))
    by_call.send_columns("world/bodies/link", indexes=times,
                         columns=rr.Transform3D.columns(translation=translation, quaternion=quat))
    by_call.send_columns("world/end_effector", indexes=times, columns=rr.Points3D.columns(positions=hand))
    by_call.flush()
    by_call.disconnect()

    for per_entity in (False, True):  # (one batch a time column; one an entity, as a real-time run sends them)
        columns = EntityColumns()
        columns.scalars("joints/a/measured_deg", t, joint)
        columns.scalars("joint_velocity_deg_s", t, wide)
        columns.scalars("joints/a/limits_deg", t_other[:2], limits)
        columns.transforms("world/bodies/link", t, translation, quat)
        columns.points("world/end_effector", t, hand)
        assert len(columns) == 6  # (a transform: its translation and its rotation)
        batches = columns.take(per_entity=per_entity)
        assert len(batches) == (5 if per_entity else 2) and len(columns) == 0
        batched = rr.RecordingStream("rehabkit-test")
        batched.save(tmp_path / f"batched{per_entity}.rrd")
        for batch in batches:
            batched.send_record_batch(batch)
        batched.flush()
        batched.disconnect()

        expected, got = _contents(tmp_path / "calls.rrd"), _contents(tmp_path / f"batched{per_entity}.rrd")
        assert set(got) == {"/joints/a/measured_deg", "/joint_velocity_deg_s", "/joints/a/limits_deg",
                            "/world/bodies/link", "/world/end_effector"}
        assert got == expected
        assert got["/world/bodies/link"]["Transform3D:quaternion"][0] == "rerun.components.RotationQuat"
        assert len(got["/joint_velocity_deg_s"]["Scalars:scalars"][1]) == 40
