"""Run one scenario: assemble, open a session, loop, finish.

The data flow, in order: validated scenario → :func:`~rehabkit.core.setup.assembly.assemble`
(robot, narrowed limits, plugins, safety layer, admitted targets) →
:func:`~rehabkit.core.run.session.open_session` (the run's state, standing at the start with its first plan) →
:func:`~rehabkit.core.run.loop.run_loop` (events → sensors → controller → safety layer → backend) →
:func:`finish` (:class:`~rehabkit.core.results.record.RunRecord` → metrics, ``summary.json`` with the ``expect:``
verdicts, the Rerun log and the safety log alongside). The loop calls plugin objects directly; pluggy only finds
them, and calls the extensions at setup and at the end.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import time
import weakref
from collections.abc import Callable
from pathlib import Path

from threadpoolctl import threadpool_limits

from rehabkit.core.io import atomic_write_json, atomic_write_text
from rehabkit.core.kinds.interfaces import BackendFaultError
from rehabkit.core.log import safety_log
from rehabkit.core.log.safety_log import SNAPSHOT
from rehabkit.core.plugins.lifecycle import Extensions, default_extensions
from rehabkit.core.plugins.registry import PluginRegistry, default_registry
from rehabkit.core.results.ending import RunEnding, ending_of
from rehabkit.core.results.record import RunRecord
from rehabkit.core.results.summary import RunResult, summarize
from rehabkit.core.run.loop import LoopResult, bring_to_rest, run_loop
from rehabkit.core.run.session import RunSession, open_session
from rehabkit.core.run.signals import Terminated, signals_held, terminated_as_interrupt
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.setup.assembly import Assembly, SetupError, assemble

__all__ = ["SNAPSHOT", "Runner", "RunResult", "SetupError", "finish"]


class Runner:
    """Runs one loaded scenario: ``build()`` assembles it (plugins built, nothing run), ``start()`` opens its
    session standing at the start, ``run()`` does both, runs the loop and finishes."""

    def __init__(self, scenario: LoadedScenario, registry: PluginRegistry | None = None,
                 out_dir: Path | None = None, spawn: bool = False, progress: bool = False,
                 extensions: Extensions | None = None):
        self.loaded, self.sc = scenario, scenario.model
        self.registry = registry or default_registry()
        self.extensions = extensions or default_extensions()
        self.out_dir, self.spawn, self.progress = out_dir, spawn, progress
        self.setup: Assembly | None = None
        self.session: RunSession | None = None
        self._calls = _Calls()

    # the assembled plugins and the last readings, for callers that inspect a run
    robot = property(lambda self: self.setup.robot)
    backend = property(lambda self: self.setup.backend)
    sensors = property(lambda self: self.setup.sensors)
    observations = property(lambda self: {name: r.values for name, r in self.session.timeline.readings.items()})

    def build(self) -> Assembly:
        """Assemble the run (see :mod:`rehabkit.core.setup.assembly`)."""
        if broken := self.extensions.broken:
            raise SetupError("; ".join(f"extension '{b.name}' failed to load: {b.error}" for b in broken)
                             + " (fix or uninstall it)")
        self.setup = assemble(self.loaded, self.registry, self.extensions, self.out_dir,
                              plan=self._calls.plan, note=self._calls.note, latest=self._calls.latest,
                              force=self._calls.force)
        return self.setup

    def start(self) -> RunSession:
        """Build and open the session: standing at the start, the first plan made, the loop not yet run — what
        :meth:`run` does first, and what a learning environment does at each reset (it then runs the loop a
        policy period at a time with :func:`~rehabkit.core.run.loop.run_loop`'s ``k_to``)."""
        a = self.build()
        # said while assembling and opening (a link's reset names its key): the session's from now on
        self.session = open_session(a, self.spawn, self._calls.notes)
        self._calls.notes = []
        self._calls.session = weakref.ref(self.session)
        return self.session

    def run(self, prepare: Callable[[RunSession], object] | None = None) -> RunResult:
        """Build, run and finish; outputs are complete files or none — but the safety log, written as the run goes,
        which a run whose loop ran keeps (:mod:`~rehabkit.core.log.safety_log`). ``prepare(session)``: called with the
        session standing at its start, before the loop (a forked replay puts the recorded session's state into it)."""
        session = loop = None
        made = self.out_dir is not None and not self.out_dir.exists()  # (a folder this run makes: gone if it never ran)
        try:
            with terminated_as_interrupt():
                t_setup = time.perf_counter()
                session = self.start()
                if prepare is not None:
                    prepare(session)
                loop, ending = self._loop(session)
                with signals_held():  # (files closed whole: a second Ctrl-C waits for them)
                    result = finish(session, loop, loop.started - t_setup, self.out_dir, ending)
        except BaseException:
            if session is not None:
                release_backend(session.setup.backend)  # (the robot stopped first, however the run ended)
                session.view.discard()
                for tap in session.taps:
                    tap.discard()
                if session.safety_log is not None:  # (written as it went: left as it stands once the loop ran)
                    session.safety_log.discard() if loop is None else session.safety_log.abandon()
                if loop is None and self.out_dir is not None:  # a run that never ran leaves no folder
                    (self.out_dir / SNAPSHOT).unlink(missing_ok=True)
            if made and loop is None:
                with contextlib.suppress(OSError):  # (only where it is empty: nothing of anyone's removed)
                    self.out_dir.rmdir()
            raise
        else:
            session.setup.backend.close()  # (after the outputs are written; its own error is the run's)
            return result
        finally:
            if session is not None and session.threads is not None:
                session.threads.close()

    def _loop(self, session: RunSession) -> tuple[LoopResult, RunEnding]:
        """The loop, and how it ended: its course run, or cut short — Ctrl-C, SIGTERM, an error out of a plugin or
        the backend — and then the robot brought to rest by the safety layer before anything else (a second Ctrl-C
        does not cut that short)."""
        t0 = time.perf_counter()
        data = None  # (a backend fault's fields for its event)
        try:
            # a control loop's matrices are small: BLAS worker threads only spin against it, and against a bridge or
            # renderer sharing the machine
            with threadpool_limits(limits=1, user_api="blas"):
                loop = run_loop(session, self.progress)
            return loop, ending_of(session.safety.events, session.safety.tripped_at)
        except KeyboardInterrupt as exc:
            name = exc.signal if isinstance(exc, Terminated) else "SIGINT"
            said = "SIGTERM: the process was asked to stop" if name == "SIGTERM" else "Ctrl-C (SIGINT)"
            rule, how, error = "interrupt", "interrupted", None
        except BackendFaultError as exc:
            name, said, rule, how = None, str(exc), "backend", "backend-fault"
            data = exc.event_data()  # (its cause as fields, as the loop's own trip on a fault gives them)
            error = type(exc).__name__
        except Exception as exc:  # noqa: BLE001 (a plugin's error out of the loop: the run ends, the robot at rest)
            name, rule, how, error = None, "plugin-error", "plugin-fault", type(exc).__name__
            said = f"{type(exc).__name__} out of the control loop: {exc}"
            logging.getLogger(__name__).debug("the run's loop raised", exc_info=True)
        with signals_held():
            t = session.loop.k * session.setup.schedule.control_dt
            bring_to_rest(session, rule, said, data)
        loop = LoopResult(session.loop.k, time.perf_counter() - t0, session.loop.contact_steps, t0)
        return loop, RunEnding(how, said, t, name, cut_short=True, error_type=error)


def release_backend(backend) -> None:
    """The backend's end as at a normal finish (a robot brought to rest, its hardware released: its ``close``) after
    an error or Ctrl-C. A second Ctrl-C meanwhile does not cut the robot's stop short: SIGINT is held off until it
    is done (in the main thread, where Python takes signals)."""
    with signals_held(signal.SIGINT):
        try:
            backend.close()
        except Exception:  # noqa: BLE001 (the run's own error is what the user needs; the close's is logged)
            logging.getLogger(__name__).exception("closing the backend after the run's error failed")


class _Calls:
    """What the plugins' context calls back into (``Context.plan``, ``Context.note``). It reaches the session weakly:
    the session holds the context, and a strong way back would be a reference cycle keeping the run — its MuJoCo
    scene among it — alive after its last user dropped it, until a full collection."""

    def __init__(self):
        self.session: weakref.ref[RunSession] | None = None
        self.notes: list[dict] = []  # said while assembling, before there is a session

    def note(self, t: float, text: str) -> None:
        # a plugin's message for people (Context.note): the session's once there is one
        session = self.session() if self.session is not None else None
        if session is not None:
            session.note(t, text)
        else:
            self.notes.append({"t": round(t, 6), "text": text})

    def latest(self, sensor: str):
        # Context.reading: the session's latest reading of a sensor (None before the session, or its first)
        session = self.session() if self.session is not None else None
        return session.timeline.readings.get(sensor) if session is not None and session.timeline else None

    def force(self):
        # Context.interaction_force: the force the run's safety layer checked last (None before the session's first)
        session = self.session() if self.session is not None else None
        return session.force if session is not None else None

    def plan(self, t, q, qd, targets):
        # Context.plan: a controller's own plan, made by the session (controllers ask only while it runs)
        return self.session().plan_for_controller(t, q, qd, targets)


def finish(session: RunSession, loop: LoopResult, setup_s: float, out_dir: Path | None,
           ending: RunEnding | None = None) -> RunResult:
    """What a run leaves behind: the record → the summary (metrics, verdicts) and, with ``out_dir``, the recording,
    the scenario as it ran, the safety log and ``summary.json``, each written whole (:meth:`Runner.run` then closes
    the backend)."""
    a, k = session.setup, loop.steps
    extra = {}
    if session.threads is not None:  # no reading in flight while the run is summed up
        threads = session.threads
        threads.close()
        extra = {f"sensor_overruns_{name}": float(threads.overruns[name]) for name in a.sensors if name in threads}
    trace = session.trace.trimmed(k)
    session.view.executed(trace, k)
    tl, first = session.timeline, session.first_refusal
    record = RunRecord(trace, loop.wall_s, setup_s, loop.contact_steps, session.ref.goal, session.ref.movements,
                       session.plans, session.gate.metrics, tl.fired, tl.acted, session.notes, session.gate.warnings,
                       extra, no_plan=first.reason if first is not None else None,
                       # the host's interventions and the robot side's (a bridge's held commands), in time order
                       interventions=sorted(session.safety.interventions + a.backend.interventions(),
                                            key=lambda e: e.t),
                       first_contact=session.loop.first_contact, safety=session.safety,
                       extension_states=session.extension_states)
    summary = summarize(a, record, session.catalogue, session.view, ending)
    session.view.verdicts(float(trace.t[-1]) if k else 0.0, summary)
    if out_dir is not None:
        # the recording's file is finished in the background while the other files are written (its encoding
        # overlapping their disk waits), and is whole in place before the summary lists it. (Those files one after
        # the other: atomic_write_text sets the process's umask for a moment.)
        outputs, recording_written = session.view.begin_close()
        try:
            summary["outputs"] = {**outputs, "scenario": SNAPSHOT, **a.backend.outputs()}
            # the tamper-evident record of the run's safety (rehabkit audit), written as the run went, beside the
            # scenario as it ran (both written as the session opened): its rest (the robot side's interventions,
            # known now) and its end, the last hash in the summary
            log = session.safety_log
            if log is None:  # (a session opened without a folder: both written here, whole)
                snapshot = safety_log.scenario_text(a)
                atomic_write_text(out_dir / SNAPSHOT, snapshot)
                log = safety_log.open_log(a, session.safety, snapshot, out_dir)
            summary["outputs"]["safety_log"] = safety_log.LOG
            summary["safety_log_hash"] = log.close(a.backend.interventions(), summary)
        finally:  # (waited for, however the rest went)
            recording_written()
        atomic_write_json(out_dir / "summary.json", summary)
    return RunResult(summary, trace, out_dir, first.located if first is not None else None, ending)
