"""What a run draws in its Rerun recording: the scene, targets, plans, the joint series, the safety events.

A run without a recording gets a :class:`NullView`: the same methods, doing nothing, so no caller asks whether
there is a log (the loop reads ``active`` once, to log no step).

The joint series are sent in columns at the scenario's log rate, ``flush_samples``
at a time (a send costs ~0.5 ms whatever its length: a file takes big batches, a
live viewer ones small enough to follow the run); a planner whose joint space is worth looking at (it returns
``joint_space_visuals``: a 3-DoF robot's collision map) gets that space drawn too,
with every plan and the executed path in it (each axis in its joint's own unit: degrees, metres for a slide).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from rehabkit.core.kinds.capabilities import SceneGeometry
from rehabkit.core.kinds.interfaces import BodyPoses, Patient, Plan
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.setup.assembly import Assembly

NO_BODIES = BodyPoses([], np.zeros((0, 3)), np.zeros((0, 4)))
LOG_FLUSH_SAMPLES = 2000  # log-rate samples buffered between column sends to a file
LIVE_FLUSH_SAMPLES = 500  # ... and when a viewer shows the run as it goes
FLUSH_EVERY_S = 1.0  # ... or this much wall time: a killed run's recording holds all but its last second


def open_view(setup: Assembly, spawn: bool = False) -> RunView | NullView:
    """The run's recording (``run.rrd`` in the run's folder, or a viewer with ``spawn``), or none."""
    if setup.out_dir is None or not setup.sc.logging.rrd:
        return NullView()
    setup.out_dir.mkdir(parents=True, exist_ok=True)
    return RunView(setup, spawn)


class RunView:
    """The run's recording."""

    active = True

    def __init__(self, setup: Assembly, spawn: bool = False):
        self.setup, self.space = setup, setup.space
        # a logged step's poses: the backend's where it tracks the bodies and the hand, else the robot's kinematics
        self._drawn = isinstance(setup.backend, SceneGeometry)
        patient = setup.patient
        self._draws = patient.drawing if patient is not None and type(patient).drawing is not Patient.drawing else None
        self.flush_samples = LIVE_FLUSH_SAMPLES if spawn else LOG_FLUSH_SAMPLES
        self._flush_by = time.monotonic() + FLUSH_EVERY_S
        self._upto = 0
        self._joint_space = False
        # Rerun (~0.3 s to import, with pyarrow) only where a run is recorded: a sweep's or a test's runs often are not
        from rehabkit.core.log.rerun_log import RerunLog

        sc, out = setup.sc, setup.out_dir
        model = setup.robot.model
        log = RerunLog(out / "run.rrd", sc.logging.application_id, model.joint_names, spawn=spawn,
                       revolute=model.revolute)
        if self._drawn:
            log.scene(setup.backend.visual_geoms())
        named = [(n, t) for n, t in setup.targets.items() if t.pose is not None]
        targets = model.to_world([t.pose[:3, 3] for _, t in named]) if named else np.zeros((0, 3))
        log.targets(0.0, [n for n, _ in named], targets)
        log.frame_on(targets)
        if (box := setup.safety.keep_in) is not None:
            log.box("world/safety/keep_in", *box, (230, 150, 30), "keep-in box (the hand stays inside)")
            log.frame_on(np.array(box))
        for name, points in setup.planner.joint_space_visuals().items():
            self._joint_space = log.contents.joint_space = True
            log.points(f"joint_space/{name}", log.in_own_units(points), (200, 80, 80), 0.4)
        self.log = log
        # a reading's way into the log, looked up once (sensors read at up to the control rate)
        self._add_reading = log._sensors.add
        self._channels = {name: sensor.channels for name, sensor in setup.sensors.items()}
        self._framed = False
        if spawn:  # a live viewer lays the run out as it comes (the file gets the final layout at the end)
            log.send_layout()

    def record_step(self, t: float, k: int, q: np.ndarray, trace: Trace) -> None:
        """A logged step: the bodies' poses and the hand (the backend's, where it tracks them; else the robot's
        kinematics), a simulated person's drawings, and the joint series when enough are buffered."""
        a, log = self.setup, self.log
        if self._drawn:
            bodies, hand = a.backend.body_poses(), a.backend.ee_position()
        else:
            bodies, hand = NO_BODIES, a.robot.ee_world(q[None])[0]
        log.record(t, bodies, hand)
        if not self._framed:  # the 3-D view holds the bodies where they start, the targets and the hand's path
            self._framed = True
            log.frame_on(bodies.positions)
        if self._draws is not None:
            for name, shapes in self._draws().items():
                log.drawing(t, f"world/patient/{name}", shapes)
        if log.pending >= self.flush_samples or time.monotonic() >= self._flush_by:
            self.flush(trace, k + 1)

    def event(self, t: float, text: str, level: str = "INFO") -> None:
        """A line in the recording's text log (an event, a note, a warning)."""
        self.log.event(t, text, level=level)

    def verdicts(self, t: float, summary: dict) -> None:
        """The summary's verdicts at the end of the text log, as the terminal says them."""
        for e in summary["expectations"]:
            value = "missing" if e["value"] is None else f"{e['value']:.6g}"
            why = f"  — {e['reason']}" if e.get("reason") else ""
            self.log.event(t, f"{'PASS' if e['passed'] else 'FAIL'}  {e['metric']} = {value}  (expected {e['bound']})"
                           + why, level="INFO" if e["passed"] else "ERROR")
        self.log.event(t, f"run {'PASSED' if summary['passed'] else 'FAILED'}",
                       level="INFO" if summary["passed"] else "ERROR")

    def sensor(self, t: float, name: str, reading: dict) -> None:
        """A sensor's reading, and where it saw a target."""
        self._add_reading(t, name, reading, self._channels.get(name) or self.setup.sensors[name].channels)
        if "target_position" in reading and reading["target_position"] is not None:
            self.log.points(f"world/sensed/{name}", self.setup.robot.model.to_world(reading["target_position"]),
                            (40, 220, 40), 0.02, t)

    def planner_drawings(self) -> None:
        """The planner's drawings; after the first plan, as some come from it (a throw's parabola)."""
        for name, points in self.setup.planner.visuals().items():
            self.log.points(f"world/planner/{name}", self.setup.robot.model.to_world(points), (120, 120, 200), 0.003)

    def plan(self, t: float, plan: Plan, x: np.ndarray) -> None:
        """A plan's hand path and waypoints (``x``: its reference at the control rate from ``t``)."""
        every, way = self.setup.schedule.log_every, plan.waypoints
        path = self.space.hand_world(x[::every])
        way_w = self.space.hand_world(way) if way is not None else np.zeros((0, 3))
        if self._joint_space:  # (a joint-space planner's own drawing)
            self.log.line("joint_space/plan", self.log.in_own_units(x[::every]), (60, 160, 255), 0.3, t)
            if way is not None:
                self.log.points("joint_space/task_points", self.log.in_own_units(way), (60, 160, 255), 1.0, t)
        self.log.plan(t, path, way_w)

    def flush(self, trace: Trace, upto: int) -> None:
        """Send the joint series recorded since the last flush, at the log rate, and the buffered poses."""
        self._flush_by = time.monotonic() + FLUSH_EVERY_S
        every = self.setup.schedule.log_every
        sel = slice(self._upto, upto, every)
        self.log.joint_series(trace.t[sel], trace.q[sel], trace.qd[sel], trace.tau[sel], trace.q_ref[sel])
        self.log.flush()
        self._upto = sel.start + len(trace.t[sel]) * every

    def executed(self, trace: Trace, k: int) -> None:
        """The rest of the joint series, and the executed path in the joint space where it is drawn."""
        self.flush(trace, k)
        limits = self.setup.safety.limits  # the ranges the run kept to (the envelope's, where narrower)
        self.log.joint_limits(float(trace.t[k - 1]) if k else 0.0, limits.lower, limits.upper)
        if self._joint_space and k:
            self.log.line("joint_space/executed", self.log.in_own_units(trace.q[:k:10]), (250, 180, 40), 0.3)
        self.log.encode_now()

    def finish(self, interventions: list, series: Callable[[], dict[str, tuple[np.ndarray, np.ndarray]]]) -> None:
        """The safety layer's interventions as events, and the run's series (backend, plugins, extensions); after it,
        only text lines (:meth:`event`, :meth:`verdicts`) are logged."""
        for ev in interventions:
            self.log.safety_event(ev)
        for path, (t, values) in series().items():
            self.log.series(path, np.asarray(t, float), np.asarray(values, float))
        # all the recording holds but the verdicts' lines is known: sent, laid out and encoded while the run is
        # summed up
        self.log.begin_settle()

    def close(self) -> dict[str, str]:
        """The recording written whole; what the summary lists of it."""
        outputs, wait = self.begin_close()
        wait()
        return outputs

    def begin_close(self) -> tuple[dict[str, str], Callable[[], object]]:
        """What the summary lists of the recording, and the call that waits for the file to be whole in place (it is
        finished in the background meanwhile: :meth:`RerunLog.begin_close`)."""
        return {"rrd": "run.rrd"}, self.log.begin_close()

    def discard(self) -> None:
        """The run failed: no half-written recording is left."""
        self.log.discard()


class NullView:
    """No recording: every method of :class:`RunView`, doing nothing."""

    active = False
    log = None
    flush_samples = 0

    def _nothing(self, *args, **kwargs) -> None:
        return None

    record_step = event = verdicts = sensor = planner_drawings = plan = flush = executed = finish = discard = _nothing

    def close(self) -> dict[str, str]:
        return {}

    def begin_close(self) -> tuple[dict[str, str], Callable[[], object]]:
        return {}, self._nothing
