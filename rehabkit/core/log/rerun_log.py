"""The Rerun sink of a run.

Row-by-row ``rr.log`` costs tens of microseconds a call, more than a whole
control step, so poses are buffered at the log rate and, with the joint series
the runner already records, sent as columns (``send_columns``) every few
simulated seconds and at the end. The file is written as ``run.rrd.tmp`` and renamed when complete; its end
(encoding and writing what is left) can go on in a background thread while the run is summed up
(:meth:`RerunLog.begin_close`), joined before the rename.
"""

from __future__ import annotations

import contextlib
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
from rehabkit.core.log import background
from rehabkit.core.log.archetypes import LIMIT_RGB, PALETTE, entity_part, paler, shape, xyzw
from rehabkit.core.log.blueprint import Contents, blueprint, labelled
from rehabkit.core.log.buffers import TIMELINE, Drawings, SensorSeries
from rehabkit.core.log.entity_columns import EntityColumns

# the joints' shared series: entity → (what it shows, its unit, whether it holds the revolute joints or the prismatic
# ones)
JOINT_SERIES = {"joint_velocity_deg_s": ("speed", "deg/s", True), "joint_torque_nm": ("effort", "N·m", True),
                "tracking_error_deg": ("error", "deg", True), "joint_velocity_m_s": ("speed", "m/s", False),
                "joint_force_n": ("effort", "N", False), "tracking_error_m": ("error", "m", False)}


class RerunLog:
    """Buffers a run's data and writes it to ``path`` (optionally also to a spawned viewer)."""

    def __init__(self, path: Path, application_id: str, joint_names: list[str], spawn: bool = False,
                 revolute: list[bool] | np.ndarray | None = None):
        """``revolute``: which joints turn (their panels in degrees), the others slide (in metres); default all."""
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
        self.joint_parts = [entity_part(j) for j in joint_names]
        self.revolute = np.ones(len(joint_names), bool) if revolute is None else np.asarray(revolute, bool)
        # each joint in its own unit: a revolute joint's angle in degrees, a prismatic joint's position in metres
        self.units = ["deg" if r else "m" for r in self.revolute]
        self._scale = np.where(self.revolute, np.degrees(1.0), 1.0)
        self.contents = Contents(self.joint_parts, self.units)
        # in wall-clock runs the column sends are queued and sent one per tick (:meth:`send_one`): a whole
        # flush (~6-8 ms here) in one tick would outlast a robot link's command watchdog
        self.deferred = False
        self._queue: deque[Callable[[], None]] = deque()
        self._rows: list[tuple] = []
        self._columns = EntityColumns()  # the series gathered until a flush sends them in one call
        self._closing: Callable[[], None] | None = None
        self._settling: Callable[[], None] | None = None  # (the end's first part, begun early: begin_settle)
        self._ee_path: list[np.ndarray] = []
        rec = self.rec
        self._drawings, self._sensors = Drawings(), SensorSeries(rec, self.contents)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for i, (name, part, u) in enumerate(zip(joint_names, self.joint_parts, self.units)):
            rgb = PALETTE[i % len(PALETTE)]
            rec.log(f"joints/{part}/measured_{u}", rr.SeriesLines(names=[f"{name} measured [{u}]"], colors=[rgb],
                                                                  widths=[2.0]), static=True)
            rec.log(f"joints/{part}/reference_{u}", rr.SeriesLines(names=[f"{name} reference [{u}]"],
                                                                   colors=[paler(rgb)], widths=[1.25]), static=True)
            rec.log(f"joints/{part}/limits_{u}", rr.SeriesLines(
                names=[f"{name} lower limit [{u}]", f"{name} upper limit [{u}]"], colors=[LIMIT_RGB] * 2,
                widths=[1.0, 1.0]), static=True)
        for series, (_, unit, turns) in JOINT_SERIES.items():
            which = [i for i, r in enumerate(self.revolute) if r == turns]
            if which:
                rec.log(series, rr.SeriesLines(names=[f"{joint_names[i]} [{unit}]" for i in which],
                                               colors=[PALETTE[i % len(PALETTE)] for i in which]), static=True)

    # -- static content -----------------------------------------------------

    def scene(self, geoms: list[GeomVisual]) -> None:
        """Geometry of every body, each geom at its fixed offset in its body."""
        for g in geoms:
            parent = "world/scene" if g.body == "world" else f"world/bodies/{entity_part(g.body)}"
            archetype = shape(g)
            if archetype is None:
                continue
            path = f"{parent}/{entity_part(g.name)}"
            self.rec.log(path, rr.Transform3D(translation=g.position, quaternion=xyzw(g.quat_wxyz)), static=True)
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

    def box(self, path: str, lo: np.ndarray, hi: np.ndarray, color: tuple[int, int, int], label: str) -> None:
        """An axis-aligned box drawn as its edges (static), e.g. the safety envelope's keep-in box."""
        self.rec.log(path, rr.Boxes3D(mins=[lo], sizes=[np.asarray(hi) - np.asarray(lo)], colors=[color],
                                      labels=[label], fill_mode="majorwireframe", radii=0.004), static=True)

    def line(self, path: str, points: np.ndarray, color: tuple[int, int, int], radius: float,
             t: float | None = None) -> None:
        """A polyline: static when ``t`` is None, else at time ``t``."""
        if t is not None:
            self.rec.set_time(TIMELINE, duration=t)
        self.rec.log(path, rr.LineStrips3D([points], colors=[color], radii=radius), static=t is None)

    def drawing(self, t: float, path: str, shapes: Drawing) -> None:
        """Shapes that change during the run, at time ``t`` (copied; sent as columns with the poses)."""
        self._drawings.add(t, path, shapes)

    def event(self, t: float, text: str, level: str = "WARN") -> None:
        self.rec.set_time(TIMELINE, duration=t)
        self.rec.log("events", rr.TextLog(text, level=level))

    def safety_event(self, ev) -> None:
        """A safety layer's event: its line in the text log, its fields beside it (shown when it is selected)."""
        where = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in
                          (("joint", ev.joint), ("value", ev.value), ("limit", ev.limit)) if v is not None)
        self.rec.set_time(TIMELINE, duration=ev.t)
        self.rec.log("events", rr.TextLog(f"SAFETY {ev.rule}" + (f" ({where})" if where else "") + f": {ev.message}",
                                          level=ev.level),
                     rr.AnyValues(rule=ev.rule, joint=ev.joint or "", value=np.nan if ev.value is None else ev.value,
                                  limit=np.nan if ev.limit is None else ev.limit))

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
        """Joint time series, sent as columns (rows at times ``t``): each joint in its own unit (a revolute joint's
        in degrees and N·m, a prismatic joint's in metres and N)."""
        if not len(t):
            return
        t, scale, columns = np.array(t), self._scale, self._columns
        q_own, ref_own = np.asarray(q) * scale, np.asarray(q_ref) * scale
        for i, (part, u) in enumerate(zip(self.joint_parts, self.units)):
            columns.scalars(f"joints/{part}/measured_{u}", t, q_own[:, i])
            columns.scalars(f"joints/{part}/reference_{u}", t, ref_own[:, i])
        values = {"speed": np.asarray(qd) * scale, "effort": np.array(tau), "error": ref_own - q_own}
        for series, (what, _, turns) in JOINT_SERIES.items():
            which = self.revolute == turns
            if which.any():
                columns.scalars(series, t, values[what] if which.all() else values[what][:, which])

    def in_own_units(self, q: np.ndarray) -> np.ndarray:
        """Joint values [rad, m] (rows of ``dof``) in each joint's own unit, as the log shows them: a revolute
        joint's in degrees, a prismatic joint's in metres."""
        return np.asarray(q, float) * self._scale

    def joint_limits(self, t_end: float, lower: np.ndarray, upper: np.ndarray) -> None:
        """Each joint's range as two flat lines over the run, in its position panel (in its own unit)."""
        t = np.array([0.0, max(t_end, 1e-3)])
        for i, (part, u) in enumerate(zip(self.joint_parts, self.units)):
            both = np.array([[lower[i], upper[i]]] * 2) * self._scale[i]
            if np.all(np.isfinite(both)):
                self._columns.scalars(f"joints/{part}/limits_{u}", t, both)

    def frame_on(self, points_world: np.ndarray) -> None:
        """Points the 3-D view must hold (the robot's bodies, the person, the targets)."""
        self.contents.scene_points.append(np.asarray(points_world, float).reshape(-1, 3))

    def series(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """A scalar time series sent as one column (e.g. a link's latency per tick)."""
        if len(t):
            values = np.array(values, float)
            self.rec.log(path, rr.SeriesLines(names=[labelled(path.split("/")[-1])]), static=True)
            self.contents.add_series(path)
            self._columns.scalars(path, np.array(t, float), values)

    def sensor(self, t: float, sensor: str, reading: dict,
               channels: Callable[[str, int], list[str] | None] | None = None) -> None:
        """A sensor reading: images are logged at once, numbers buffered in columns; ``channels(key, width)`` names
        a vector's values (:meth:`Sensor.channels`)."""
        self._sensors.add(t, sensor, reading, channels)

    def flush(self) -> None:
        """Send the buffered poses, sensor readings and series as columns."""
        rows, self._rows = self._rows, []
        if rows:
            times = np.array([r[0] for r in rows])
            names = rows[0][1].names
            pos = np.array([r[1].positions for r in rows])
            quat = xyzw(np.array([r[1].quats_wxyz for r in rows]))
            for i, name in enumerate(names):
                self._columns.transforms(f"world/bodies/{entity_part(name)}", times, pos[:, i], quat[:, i])
            self._columns.points("world/end_effector", times, np.array(self._ee_path[-len(rows):]))
        self._drawings.flush(self._send)
        self._sensors.flush(self._columns)
        if len(self._columns):  # (in a real-time run, an entity a tick: see send_one)
            for batch in self._columns.take(per_entity=self.deferred):
                if self.deferred:
                    self._queue.append(lambda b=batch: self.rec.send_record_batch(b))
                else:
                    self.rec.send_record_batch(batch)

    def encode_now(self) -> None:
        """Have Rerun encode and write what it holds now, in its own threads, without waiting (its batcher would wait
        for its next tick or the close): a run's series, sent at its end, are encoded while the run is summed up."""
        self.rec.flush(timeout_sec=0.0)

    def _send(self, path: str, t: np.ndarray, columns: Callable[[], Any]) -> None:
        """Send one entity's columns now, or queue it in deferred mode (``columns`` builds them then)."""
        def send() -> None:
            self.rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=columns())
        if self.deferred:
            self._queue.append(send)
        else:
            send()

    def send_layout(self) -> None:
        """The recording's blueprint, for what it holds now (sent at the start of a live run, and at the end)."""
        self.rec.send_blueprint(blueprint(self.contents), make_active=True, make_default=True)

    @property
    def queued(self) -> int:
        return len(self._queue)

    def send_one(self) -> None:
        """Send the oldest queued entity's columns (deferred mode: one per control tick)."""
        if self._queue:
            self._queue.popleft()()

    def discard(self) -> None:
        """Drop an unfinished recording (a run that died outside plugin code)."""
        for pending in (self._settling, self._closing):  # (its end under way in the background: waited for, dropped)
            if pending is not None:
                with contextlib.suppress(Exception):
                    pending()
        self.rec.disconnect()
        self.tmp.unlink(missing_ok=True)

    def begin_settle(self) -> None:
        """Send everything buffered, the hand's path and the layout in a background thread, the file's encoding
        started: what the recording's end can do once nothing but text events (:meth:`event`) is logged any more,
        while the caller sums the run up. :meth:`begin_close` waits for it."""
        if self._settling is None:
            self._settling = background.begin(self._settle, name="rerun-settle")

    def _settle(self) -> None:
        self.flush()
        while self._queue:
            self.send_one()
        if self._ee_path:
            path = np.array(self._ee_path)
            self.rec.log("world/end_effector_path", rr.LineStrips3D([path], colors=[[250, 180, 40]], radii=0.004),
                         static=True)
            self.frame_on(path)
        self.send_layout()
        self.encode_now()

    def begin_close(self) -> Callable[[], Path]:
        """Finish the recording in a background thread — send everything left and the layout (:meth:`begin_settle`,
        unless it was begun), encode and write it — while the caller writes its other files (their disk waits leave
        the interpreter free for it); returns the call that waits for it and moves the file into place (until then
        it is ``run.rrd.tmp``: the file is whole at its name or not there). Nothing is logged to this log once it is
        called."""
        written = background.begin(self._end, name="rerun-close")
        self._closing = written

        def wait() -> Path:
            written()
            os.replace(self.tmp, self.path)
            return self.path
        return wait

    def _end(self) -> None:
        settled, self._settling = self._settling, None
        if settled is not None:
            settled()
        else:
            self._settle()
        self.flush()  # (whatever came after the settling: nothing, or a straggler's columns)
        self.rec.flush()
        self.rec.disconnect()

    def close(self) -> Path:
        """Flush everything, finish the file and move it into place."""
        return self.begin_close()()
