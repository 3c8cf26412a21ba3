"""The Rerun sink of a run.

Row-by-row ``rr.log`` costs tens of microseconds a call, more than a whole
control step, so poses are buffered at the log rate and, with the joint series
the runner already records, sent as columns (``send_columns``) every few
simulated seconds and at the end. The file is written as ``run.rrd.tmp`` and renamed when complete.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from rehabkit.core.kinds.interfaces import BodyPoses, Drawing, GeomVisual

TIMELINE = "sim_time"


def _rgba(c) -> list[int]:
    return [int(round(255 * v)) for v in c]


def _rgba_rows(rgba) -> np.ndarray | None:
    return None if rgba is None else np.round(255 * np.clip(np.asarray(rgba, float), 0, 1)).astype(np.uint8)


def _xyzw(wxyz: np.ndarray) -> np.ndarray:
    return np.asarray(wxyz)[..., [1, 2, 3, 0]]


def _shape(g: GeomVisual):
    """A Rerun archetype for a primitive, in the geom's own frame."""
    color = [_rgba(g.rgba)]
    if g.shape == "sphere":
        return rr.Ellipsoids3D(half_sizes=[[g.size[0]] * 3], colors=color, fill_mode="solid")
    if g.shape == "ellipsoid":
        return rr.Ellipsoids3D(half_sizes=[g.size], colors=color, fill_mode="solid")
    if g.shape == "box":
        return rr.Boxes3D(half_sizes=[g.size], colors=color, fill_mode="solid")
    if g.shape == "plane":
        return rr.Boxes3D(half_sizes=[[g.size[0], g.size[1], 0.001]], colors=color, fill_mode="solid")
    if g.shape == "cylinder":
        return rr.Cylinders3D(lengths=[2 * g.size[1]], radii=[g.size[0]], colors=color, fill_mode="solid")
    if g.shape == "mesh" and g.mesh is not None:
        return rr.Mesh3D(vertex_positions=g.mesh[0], triangle_indices=g.mesh[1], albedo_factor=color[0])
    if g.shape == "capsule":  # Rerun's capsule starts at the origin; MuJoCo's is centred
        return rr.Capsules3D(lengths=[2 * g.size[1]], radii=[g.size[0]], translations=[[0, 0, -g.size[1]]],
                             colors=color, fill_mode="solid")
    return None


def is_image(value: Any) -> bool:
    """An RGB image as sensors give them: ``HxWx3`` uint8."""
    return isinstance(value, np.ndarray) and value.ndim == 3 and value.shape[2] == 3 and value.dtype == np.uint8


def encode_image(rgb: np.ndarray) -> rr.EncodedImage:
    """JPEG for the log (OpenCV's encoder: ~4x faster than Rerun's own here, and it lets other threads run)."""
    import cv2  # only runs with cameras pay for importing OpenCV

    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise ValueError("could not encode an image for the log")
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg")


def encode_images(reading: dict[str, Any]) -> dict[str, Any]:
    """The reading with its images encoded for the log (done where the reading is made, off the loop)."""
    return {k: encode_image(v) if is_image(v) else v for k, v in reading.items()}



def _part(name: str) -> str:
    """A model's name as one entity-path part (MyoSuite names hold spaces, which Rerun warns about)."""
    return name.replace(" ", "_")

class _Column:
    """One sensor value's readings, appended in place (no per-sample list to convert at the flush)."""

    def __init__(self, width: int, what: str):
        self.t, self.values, self.n, self.what = np.empty(256), np.empty((256, width)), 0, what

    def append(self, t: float, value) -> None:
        n = self.n
        if n == len(self.t):
            self.t = np.resize(self.t, 2 * n)
            self.values = np.resize(self.values, (2 * n, self.values.shape[1]))
        try:
            self.values[n] = value
        except ValueError:
            raise ValueError(f"{self.what}: {np.size(value)} values, {self.values.shape[1]} in its earlier "
                             "readings (a reading's arrays keep their size; log a changing set as points)") from None
        self.t[n] = t
        self.n = n + 1

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """The buffered (times, values), copied; the buffer starts over."""
        n, self.n = self.n, 0
        return self.t[:n].copy(), self.values[:n].copy()


class RerunLog:
    """Buffers a run's data and writes it to ``path`` (optionally also to a spawned viewer)."""

    def __init__(self, path: Path, application_id: str, joint_names: list[str], spawn: bool = False):
        self.path = Path(path)
        self.tmp = self.path.with_name(self.path.name + ".tmp")
        self.rec = rr.RecordingStream(application_id)
        self.rec.save(self.tmp)
        if spawn and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                               or os.environ.get("WAYLAND_DISPLAY")):
            warnings.warn(f"--spawn: no display here, so no viewer; writing {self.path} only", stacklevel=2)
        elif spawn:
            try:
                self.rec.spawn(connect=False)
                self.rec.set_sinks(rr.FileSink(str(self.tmp)), rr.GrpcSink())
            except Exception as exc:  # no viewer binary: the file is what matters
                warnings.warn(f"--spawn: could not start the Rerun viewer ({exc}); writing {self.path} only",
                              stacklevel=2)
        self.joint_names = joint_names
        # in wall-clock runs the column sends are queued and sent one per tick (:meth:`send_one`): a whole
        # flush (~6-8 ms here) in one tick would outlast a robot link's command watchdog
        self.deferred = False
        self._queue: deque[Callable[[], None]] = deque()
        self._rows: list[tuple] = []
        self._ee_path: list[np.ndarray] = []
        self._sensor_columns: dict[str, dict[str, _Column]] = {}  # sensor -> reading key -> its column
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for series in ("position_deg", "reference_deg", "velocity_deg_s", "torque_nm", "tracking_error_deg"):
            rec.log(f"joints/{series}", rr.SeriesLines(names=joint_names), static=True)

    # -- static content -----------------------------------------------------

    def scene(self, geoms: list[GeomVisual]) -> None:
        """Geometry of every body, each geom at its fixed offset in its body."""
        for g in geoms:
            parent = "world/scene" if g.body == "world" else f"world/bodies/{_part(g.body)}"
            archetype = _shape(g)
            if archetype is None:
                continue
            path = f"{parent}/{_part(g.name)}"
            self.rec.log(path, rr.Transform3D(translation=g.position, quaternion=_xyzw(g.quat_wxyz)), static=True)
            self.rec.log(path, archetype, static=True)

    def targets(self, t: float, names: list[str], positions_world: np.ndarray) -> None:
        self.rec.set_time(TIMELINE, duration=t)
        self.rec.log("world/targets", rr.Points3D(positions_world, labels=names, radii=0.015,
                                                   colors=[[230, 60, 60]] * len(names), show_labels=True))

    def plan(self, t: float, ee_path_world: np.ndarray, waypoints_world: np.ndarray) -> None:
        """A new plan: the end-effector path it implies and its via points."""
        self.rec.set_time(TIMELINE, duration=t)
        self.rec.log("world/plan/path", rr.LineStrips3D([ee_path_world], colors=[[60, 160, 255]], radii=0.003))
        self.rec.log("world/plan/waypoints", rr.Points3D(waypoints_world, colors=[[60, 160, 255]], radii=0.012))

    def points(self, path: str, positions_world: np.ndarray, color: tuple[int, int, int], radius: float,
               t: float | None = None) -> None:
        """A point set: static when ``t`` is None, else at time ``t``."""
        if t is not None:
            self.rec.set_time(TIMELINE, duration=t)
        self.rec.log(path, rr.Points3D(positions_world, colors=[color], radii=radius), static=t is None)

    def line(self, path: str, points: np.ndarray, color: tuple[int, int, int], radius: float,
             t: float | None = None) -> None:
        """A polyline: static when ``t`` is None, else at time ``t``."""
        if t is not None:
            self.rec.set_time(TIMELINE, duration=t)
        self.rec.log(path, rr.LineStrips3D([points], colors=[color], radii=radius), static=t is None)

    def drawing(self, t: float, path: str, shapes: Drawing) -> None:
        """Shapes that change during the run, at time ``t`` (logged as they come: a few per log sample)."""
        def send() -> None:
            self.rec.set_time(TIMELINE, duration=t)
            if shapes.lines is not None:
                self.rec.log(f"{path}/lines", rr.LineStrips3D(shapes.lines, colors=_rgba_rows(shapes.line_rgba),
                                                              radii=0.003))
            if shapes.origins is not None:
                self.rec.log(f"{path}/arrows", rr.Arrows3D(origins=shapes.origins, vectors=shapes.vectors,
                                                           colors=_rgba_rows(shapes.arrow_rgba), radii=0.006))
        if self.deferred:
            self._queue.append(send)
        else:
            send()

    def event(self, t: float, text: str, level: str = "WARN") -> None:
        self.rec.set_time(TIMELINE, duration=t)
        self.rec.log("events", rr.TextLog(text, level=level))

    # -- time series --------------------------------------------------------

    def record(self, t: float, bodies: BodyPoses, ee_world: np.ndarray) -> None:
        """One log-rate sample of the 3-D scene (keeps the arrays it is given: pass copies)."""
        self._rows.append((t, bodies))
        self._ee_path.append(ee_world)

    @property
    def pending(self) -> int:
        """Samples buffered since the last flush."""
        return len(self._rows)

    def joint_series(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, q_ref: np.ndarray) -> None:
        """Joint time series, sent as columns (rows at times ``t``)."""
        if not len(t):
            return
        t, deg = np.array(t), np.degrees
        for series, values in (("position_deg", deg(q)), ("reference_deg", deg(q_ref)), ("velocity_deg_s", deg(qd)),
                               ("torque_nm", np.array(tau)), ("tracking_error_deg", deg(q_ref - q))):
            self._send(f"joints/{series}", t, lambda v=values: rr.Scalars.columns(scalars=v))

    def series(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """A scalar time series sent as one column (e.g. a link's latency per tick)."""
        if len(t):
            values = np.array(values, float)
            self._send(path, np.array(t, float), lambda: rr.Scalars.columns(scalars=values))

    def sensor(self, t: float, sensor: str, reading: dict) -> None:
        """A sensor reading: images are logged at once, numbers buffered in columns."""
        columns = self._sensor_columns.get(sensor)
        if columns is None:
            columns = self._sensor_columns[sensor] = {}
        for key, value in reading.items():
            if value is None:
                continue
            if type(value) is not float and not (type(value) is np.ndarray and value.ndim == 1):
                if isinstance(value, rr.EncodedImage) or is_image(value):
                    self.rec.set_time(TIMELINE, duration=t)
                    self.rec.log(f"sensors/{sensor}/{key}", value if isinstance(value, rr.EncodedImage) else
                                 encode_image(value))
                    continue
                value = np.ravel(np.asarray(value, float))
            column = columns.get(key)
            if column is None:
                column = columns[key] = _Column(np.size(value), f"sensor '{sensor}' {key}")
            column.append(t, value)

    def flush(self) -> None:
        """Send buffered poses and sensor readings as columns."""
        rows, self._rows = self._rows, []
        if rows:
            times = np.array([r[0] for r in rows])
            names = rows[0][1].names
            pos = np.array([r[1].positions for r in rows])
            quat = _xyzw(np.array([r[1].quats_wxyz for r in rows]))
            for i, name in enumerate(names):
                self._send(f"world/bodies/{_part(name)}", times,
                           lambda i=i: rr.Transform3D.columns(translation=pos[:, i], quaternion=quat[:, i]))
            ee = np.array(self._ee_path[-len(rows):])
            self._send("world/end_effector", times, lambda: rr.Points3D.columns(positions=ee.reshape(-1, 3)))
        for sensor, columns in self._sensor_columns.items():
            for key, column in columns.items():
                if column.n:
                    t, values = column.take()
                    self._send(f"sensors/{sensor}/{key}", t, lambda v=values: rr.Scalars.columns(scalars=v))

    def _send(self, path: str, t: np.ndarray, columns: Callable[[], Any]) -> None:
        """Send one entity's columns now, or queue it in deferred mode (``columns`` builds them then)."""
        def send() -> None:
            self.rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=columns())
        if self.deferred:
            self._queue.append(send)
        else:
            send()

    @property
    def queued(self) -> int:
        return len(self._queue)

    def send_one(self) -> None:
        """Send the oldest queued entity's columns (deferred mode: one per control tick)."""
        if self._queue:
            self._queue.popleft()()

    def discard(self) -> None:
        """Drop an unfinished recording (a run that died outside plugin code)."""
        self.rec.disconnect()
        self.tmp.unlink(missing_ok=True)

    def close(self) -> Path:
        """Flush everything, finish the file and move it into place."""
        self.flush()
        while self._queue:
            self.send_one()
        if self._ee_path:
            self.rec.log("world/end_effector_path", rr.LineStrips3D([np.array(self._ee_path)],
                                                                     colors=[[250, 180, 40]], radii=0.004), static=True)
        self.rec.flush()
        self.rec.disconnect()
        os.replace(self.tmp, self.path)
        return self.path
