"""What is due besides control, step by step: task events, scene actions, sensor readings, the stop.

The loop asks :meth:`Timeline.due` only at the step it last said something is due,
so a step with nothing to do costs one integer comparison. Events fire on a time
(``at``), on the hand reaching a target (checked at ``REACH_CHECK_HZ``), or on a
sensed target having moved and settled; they plan again, move an object, or stop
(after a ramp-out, when the envelope has one). A replan is not made here: :meth:`Timeline.due` returns the
:class:`Replan` requests it found due, and the session makes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rehabkit.core.kinds.capabilities import scene_actions
from rehabkit.core.kinds.sensor import Reading
from rehabkit.core.run.plugin_fault import debug_traceback
from rehabkit.core.run.sensor_threads import SensorThreads
from rehabkit.core.run.signals import signals_deferred
from rehabkit.core.setup.assembly import Assembly

NO_REPLANS: list = []  # never appended to: what due() returns when no plan is due


@dataclass(frozen=True)
class Replan:
    """A plan due: through ``names`` (by event ``event``'s planner settings, if it has some); sensor-driven targets
    at the positions last sensed (base frame), or ``unseen`` says which sensor has not seen one yet."""

    names: list[str]
    event: int | None = None
    sensed: dict[str, np.ndarray] = field(default_factory=dict)
    unseen: str | None = None


class Timeline:
    """Events, scene actions, sensors and the stop of one run; ``view`` records events and readings."""

    # what changes while the run goes (a session snapshot takes these; the rest is the run's wiring)
    RUN_STATE_FIELDS = ("_replans", "readings", "fired", "_following", "acted", "actions", "_timed", "_waiting",
                        "_watch", "_next_reach", "stop_at", "_ramp_out_at", "_sensor_due")

    def __init__(self, setup: Assembly, view, threads: SensorThreads | None, taps: list, targets: dict, safety):
        sc, sch = setup.sc, setup.schedule
        self.setup, self.view, self.threads, self.taps = setup, view, threads, taps
        self.targets = targets  # (the session's: a sensed one where it was last seen)
        self.safety = safety  # (the session's layer: an e-stop or a plugin's fault trips it, the end ramps out)
        self._replans: list[Replan] = []
        self.events = sc.task.events
        self.specs = {t.name: t for t in sc.task.targets}
        self.readings: dict = {}  # the sensors' latest, by name: what plugins read (Context.reading, through the run)
        self._frames = {name: sensor.frame for name, sensor in setup.sensors.items()}
        self.fired: list[dict] = []
        self._following: tuple[list[str], float, np.ndarray | None] = ([], 0.0, None)
        self.acted: list[dict] = []
        self.actions: list[tuple[int, str, str]] = []  # (step, 'release' | 'grasp', object)
        self._perform = scene_actions(setup.backend)  # (a plan's actions were checked against these names)
        self._timed = sorted((round(e.at / sch.control_dt), i) for i, e in enumerate(self.events) if e.at is not None)
        self._waiting = [i for i, e in enumerate(self.events) if e.reached is not None]
        # 'moved' events: [position last planned for, candidate new position, readings it has held]
        self._watch = {i: [None, None, 0] for i, e in enumerate(self.events) if e.moved is not None}
        self._next_reach, self.stop_at, n = 0, sch.steps, sch.steps
        self._ramp_steps = int(round(sc.safety.ramp_out_s / sch.control_dt))
        self._ramp_out_at = n - self._ramp_steps if self._ramp_steps else None
        self._sensor_due = [0] * len(setup.sensors)
        # (index, name, sensor, every, read in a thread): fixed for the run, so each reading costs no lookups
        self._sensors = [(j, name, sensor, every, threads is not None and name in threads)
                         for j, ((name, sensor), every) in enumerate(zip(setup.sensors.items(), sch.sensor_every))]

    def schedule_actions(self, k0: int, actions: list[tuple[float, str, str]]) -> None:
        """A plan's scene actions (a throw's release), from step ``k0``; they replace the previous plan's."""
        dt = self.setup.schedule.control_dt
        self.actions = sorted([a for a in self.actions if a[0] < k0]
                              + [(k0 + int(round(at / dt)), kind, obj) for at, kind, obj in actions])

    def following(self, names: list[str], t0: float, times: np.ndarray | None) -> None:
        """The plan now followed: its targets, its start [s] and when it passes them (from its start)."""
        self._following = (list(names), t0, None if times is None else np.asarray(times, float))

    def remaining(self, trigger: str | None, t: float) -> list[str]:
        """Targets of the plan being followed not reached yet: after ``trigger`` (the target whose reaching fired
        the event), else those it passes after ``t``."""
        names, t0, times = self._following
        if trigger is not None and trigger in names:
            return names[names.index(trigger) + 1:]
        if times is None or len(times) < len(names):
            return names
        ahead = t0 + times[len(times) - len(names):] > t + 1e-9  # a plan's own start point comes first
        return [n for n, later in zip(names, ahead) if later]

    def sensed(self, name: str) -> np.ndarray | None:
        """Where the sensor of a sensor-driven target last saw it (base frame), if it did."""
        reading = self.readings.get(self.specs[name].sensor)
        pos = None if reading is None else reading.values.get("target_position")
        return None if pos is None else np.asarray(pos, float)

    def request(self, names: list[str], event: int | None = None) -> Replan:
        """A plan through ``names``, its sensor-driven targets where they were last sensed."""
        sensed = {}
        for name in names:
            spec = self.specs[name]
            if spec.sensor:
                pos = self.sensed(name)
                if pos is None:
                    return Replan(list(names), event, unseen=f"target '{name}': sensor '{spec.sensor}' has not seen it")
                sensed[name] = pos
        return Replan(list(names), event, sensed)

    def due(self, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> tuple[int, list[Replan]]:
        """Do what is due at step ``k`` but planning: the next step anything is due (-1: stop the run), and the
        plans due now."""
        a, sch = self.setup, self.setup.schedule
        try:
            while self._timed and self._timed[0][0] <= k:
                self._fire(self._timed.pop(0)[1], k, t, q, qd)
            while self.actions and self.actions[0][0] <= k:
                _, kind, obj = self.actions.pop(0)
                self._perform[kind](obj)
                self.acted.append({"t": round(t, 6), "action": kind, "object": obj})
                self.view.event(t, f"{kind} {obj}", level="INFO")
            if self._waiting and k >= self._next_reach:
                self._next_reach = k + sch.reach_every
                ee = a.robot.fk(q)[:3, 3]  # base frame, as target poses are
                for i in list(self._waiting):
                    ev = self.events[i]
                    if np.linalg.norm(ee - self.targets[ev.reached].pose[:3, 3]) <= ev.tolerance_m:
                        self._waiting.remove(i)
                        self._fire(i, k, t, q, qd)
            if self._ramp_out_at is not None and k >= self._ramp_out_at:
                self.safety.begin_ramp_out(t, q)
                self._ramp_out_at = None
            if k >= self.stop_at:
                return -1, self._take_replans()
            self._read_sensors(k, t, q, qd)
        except Exception as exc:
            debug_traceback(exc)
            self.safety.trip(t, q, "plugin-error", f"{type(exc).__name__} during events/sensors: {exc}", qd)
        replans = self._take_replans()
        nxt = self.stop_at
        for d in self._sensor_due:
            if d < nxt:
                nxt = d
        if self._ramp_out_at is not None and self._ramp_out_at < nxt:
            nxt = self._ramp_out_at
        if self._timed and self._timed[0][0] < nxt:
            nxt = self._timed[0][0]
        if self.actions and self.actions[0][0] < nxt:
            nxt = self.actions[0][0]
        if self._waiting and self._next_reach < nxt:
            nxt = self._next_reach
        if self.threads is not None and self.threads.busy:
            return k + 1, replans  # a sensor thread's reading is taken at the first tick after it is done
        return (nxt if nxt > k else k + 1), replans

    def _take_replans(self) -> list[Replan]:
        if not self._replans:  # (the common case: no new list each time)
            return NO_REPLANS
        replans, self._replans = self._replans, []
        return replans

    def _read_sensors(self, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        backend, threads, due = self.setup.backend, self.threads, self._sensor_due
        for j, name, sensor, every, threaded in self._sensors:
            if k >= due[j]:
                due[j] = k + every
                if threaded:
                    threads.start(name, sensor, t, q, qd, backend)
                else:
                    self._take(name, t, sensor.read(t, q, qd, backend), k, t, q, qd)
        if threads is not None:
            for name, t_read, reading in threads.finished():
                self._take(name, t_read, reading, k, t, q, qd)

    def _take(self, name: str, t_read: float, reading: dict, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        """A sensor's reading (started at ``t_read``) into the readings and the log; 'moved' events."""
        self.readings[name] = Reading(name, t_read, reading, self._frames[name])
        self.view.sensor(t_read, name, reading)
        if self.taps:
            with signals_deferred():  # (a tap's write whole: a Ctrl-C taken after it)
                for tap in self.taps:
                    tap.reading(t_read, name, reading)
        if not self._watch:
            return
        for i, state in self._watch.items():
            ev = self.events[i]
            if self.specs[ev.moved].sensor != name:
                continue
            pos = self.sensed(ev.moved)
            planned, candidate, held = state
            if pos is None or (planned is not None and np.linalg.norm(pos - planned) <= ev.tolerance_m):
                state[1], state[2] = None, 0
                continue
            if candidate is not None and np.linalg.norm(pos - candidate) <= ev.tolerance_m:
                state[2] = held + 1
            else:
                state[1], state[2] = pos, 1
            if state[2] >= ev.settle:
                state[0], state[1], state[2] = pos, None, 0
                self._fire(i, k, t, q, qd)

    def _fire(self, i: int, k: int, t: float, q: np.ndarray, qd: np.ndarray) -> None:
        ev = self.events[i]
        trigger = f"at {ev.at}" if ev.at is not None else (
            f"reached {ev.reached}" if ev.reached is not None else f"{ev.moved} moved")
        self.fired.append({"event": i, "t": round(t, 6), "action": ev.action, "trigger": trigger})
        self.view.event(t, f"event {i}: {trigger} -> {ev.action}", level="INFO")
        if ev.action == "stop":  # with a ramp-out, the robot is eased into holding first
            self.stop_at = min(self.stop_at, k + self._ramp_steps)
            if self._ramp_steps:
                self._ramp_out_at = k
        elif ev.action == "estop":  # pressed: stopped in the e-stop rule's category, latched at the robot
            a = self.setup
            why = f"e-stop pressed (event {i}, {trigger})"
            self.safety.trip(t, q, "e-stop", why, qd)
            if not a.backend.latch_estop(why):
                self.view.event(t, f"backend '{a.sc.backend.type}' keeps no e-stop latch", level="WARN")
        elif ev.action == "move":
            self.setup.backend.move_object(ev.object, np.asarray(ev.position, float))
        elif ev.moved is not None:  # a sensed target moved: reach it (the sequence) again
            self._replans.append(self.request(ev.sequence or self.setup.sc.task.order(), i))
        else:  # from where the arm is to what is left
            names = ev.sequence or self.remaining(ev.reached, t)
            if names:
                self._replans.append(self.request(names, i))
            else:
                self.view.event(t, f"event {i}: every target is reached; nothing to plan", level="INFO")
