"""What a run's log buffers between sends: drawings that change (lines, arrows) and sensor readings, each sent to
Rerun as columns (a row per sample, as a person's 60-odd muscle paths at the log rate, would cost ~1 ms a sample)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import rerun as rr

from rehabkit.core.kinds.interfaces import Drawing
from rehabkit.core.log.archetypes import Column, encode_image, in_degrees, is_image, rgba_rows, strips
from rehabkit.core.log.blueprint import Contents, labelled

TIMELINE = "sim_time"
Send = Callable[[str, np.ndarray, Callable[[], Any]], None]  # (entity, times, its columns built when sent)


class Drawings:
    """Plugins' drawings over time, per entity path: copied when given, sent as columns at each flush."""

    def __init__(self) -> None:
        self._lines: dict[str, list[tuple]] = {}  # path -> (t, points, points per line, colours) a drawing
        self._arrows: dict[str, list[tuple]] = {}  # path -> (t, origins, vectors, colours, labels) a drawing

    def add(self, t: float, path: str, shapes: Drawing) -> None:
        if shapes.lines is not None:
            lengths = np.fromiter((len(line) for line in shapes.lines), np.int32, len(shapes.lines))
            points = np.concatenate(shapes.lines) if len(lengths) else np.zeros((0, 3))
            self._lines.setdefault(path, []).append((t, points, lengths, rgba_rows(shapes.line_rgba)))
        if shapes.origins is not None:
            self._arrows.setdefault(path, []).append(
                (t, np.array(shapes.origins, float), np.array(shapes.vectors, float), rgba_rows(shapes.arrow_rgba),
                 None if shapes.arrow_labels is None else list(shapes.arrow_labels)))

    def flush(self, send: Send) -> None:
        for path, rows in self._lines.items():
            fields = {"strips": strips(np.concatenate([r[1] for r in rows]), np.concatenate([r[2] for r in rows]))}
            fields["radii"] = np.full(sum(len(r[2]) for r in rows), 0.003)
            if all(r[3] is not None for r in rows):
                fields["colors"] = np.concatenate([r[3] for r in rows])
            counts = [len(r[2]) for r in rows]
            send(f"{path}/lines", np.array([r[0] for r in rows]),
                 lambda f=fields, n=counts: rr.LineStrips3D.columns(**f).partition(n))
        for path, rows in self._arrows.items():
            fields = {"origins": np.concatenate([r[1] for r in rows]), "vectors": np.concatenate([r[2] for r in rows])}
            fields["radii"] = np.full(len(fields["origins"]), 0.006)
            if all(r[3] is not None for r in rows):
                fields["colors"] = np.concatenate([r[3] for r in rows])
            if all(r[4] is not None for r in rows):
                fields["labels"] = [label for r in rows for label in r[4]]
            counts = [len(r[1]) for r in rows]
            send(f"{path}/arrows", np.array([r[0] for r in rows]),
                 lambda f=fields, n=counts: rr.Arrows3D.columns(**f).partition(n))
        self._lines, self._arrows = {}, {}


class SensorSeries:
    """Sensor readings: images logged as they come, numbers kept in a column per reading key until a flush."""

    def __init__(self, rec: rr.RecordingStream, contents: Contents) -> None:
        self.rec, self.contents = rec, contents
        self._columns: dict[str, dict[str, Column]] = {}  # sensor -> reading key -> its column

    def add(self, t: float, sensor: str, reading: dict,
            channels: Callable[[str, int], list[str] | None] | None = None) -> None:
        columns = self._columns.get(sensor)
        if columns is None:
            columns = self._columns[sensor] = {}
        for key, value in reading.items():
            if value is None:
                continue
            if type(value) is not float and not (type(value) is np.ndarray and value.ndim == 1):
                if isinstance(value, rr.EncodedImage) or is_image(value):
                    self.contents.add_sensor(sensor, key, True)
                    self.rec.set_time(TIMELINE, duration=t)
                    self.rec.log(f"sensors/{sensor}/{key}", value if isinstance(value, rr.EncodedImage) else
                                 encode_image(value))
                    continue
                value = np.ravel(np.asarray(value, float))
            column = columns.get(key)
            if column is None:
                column = columns[key] = Column(np.size(value), f"sensor '{sensor}' {key}")
                self._name(sensor, key, np.size(value), channels)
            column.append(t, value)

    def _name(self, sensor: str, key: str, width: int, channels) -> None:
        parts = channels(key, width) if channels is not None and width > 1 else None
        if parts is not None and len(parts) != width:  # a plugin's slip: the series still logged, numbered
            warnings.warn(f"sensor '{sensor}': channels('{key}', {width}) named {len(parts)} values; numbered instead",
                          stacklevel=3)
            parts = None
        key = in_degrees(key)[0]
        label = labelled(key)
        names = [label] if width == 1 else [f"{part} {label}" for part in (parts or range(width))]
        self.rec.log(f"sensors/{sensor}/{key}", rr.SeriesLines(names=names), static=True)
        self.contents.add_sensor(sensor, key, False)

    def flush(self, out) -> None:
        """The readings since the last flush into ``out`` (an :class:`~rehabkit.core.log.entity_columns.EntityColumns`),
        a :class:`rr.Scalars` series a reading key."""
        for sensor, columns in self._columns.items():
            for key, column in columns.items():
                if column.n:
                    t, values = column.take()
                    logged, scale = in_degrees(key)
                    out.scalars(f"sensors/{sensor}/{logged}", t, values * scale)
