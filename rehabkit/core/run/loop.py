"""The control loop alone: state → (what is due) → controller → (person) → safety layer → backend.

Each step's ``[q, qd, tau]`` is one row of the trace, written in place: the
controller's torque goes into it and the safety layer overwrites it with what
is sent. Everything that is not due every step (events, sensors, logging) is
behind one integer comparison.
"""

from __future__ import annotations

import gc
import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from rehabkit.core.kinds.capabilities import Contacts, FollowsReference
from rehabkit.core.kinds.interfaces import BackendFaultError, EmbodiedPatient
from rehabkit.core.run.plugin_fault import NOTHING, plugin_fault
from rehabkit.core.run.session import RunSession
from rehabkit.core.run.signals import signals_deferred


@dataclass(frozen=True)
class LoopResult:
    steps: int  # steps run
    wall_s: float
    contact_steps: int
    started: float  # perf_counter at its first step


class _Progress:
    """A terminal's progress bar, made once the loop has run a second: a short run never imports tqdm (~60 ms)."""

    def __init__(self, steps: int):
        self.steps, self.bar = steps, None

    def tick(self, k: int, t_loop: float) -> None:
        if self.bar is not None:
            self.bar.update(1000)
        elif time.perf_counter() - t_loop > 1.0:
            from tqdm import tqdm

            self.bar = tqdm(total=self.steps, unit="step", leave=False)
            self.bar.update(k + 1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _stopped(st, safety, backend, t: float, dt: float, stop_after: float) -> bool:
    """After a trip: the brakes once the torque is off; whether the stop has run its course (the run ends)."""
    if not st.braked and safety.torque_off:
        st.braked = True
        safety.braked(t, backend.engage_brakes())
    st.stopped = t + dt - safety.tripped_at >= stop_after - 1e-9
    return st.stopped


def first_contact(t: float, c) -> dict:
    """The first contact of a run, for its summary: when, which geoms (the robot's first), where, how deep."""
    where = [round(float(v), 4) for v in c.position]
    return {"t": round(t, 6), "robot": c.geom1, "other": c.geom2, "position_m": where,
            "depth_mm": round(c.depth * 1000, 2),
            "text": f"t={t:.3f}s: contact: {c.geom1} touched {c.geom2} at ({', '.join(f'{v:.3f}' for v in where)}) m, "
                    f"{c.depth * 1000:.1f} mm deep"}


def _idle(dof: int):
    zero = np.zeros(dof)
    return lambda *args: zero


def run_loop(session: RunSession, progress: bool = False, k_to: int | None = None) -> LoopResult:
    """Advance the session until the end, a stop event, or the safety layer's stop has run its course — or, run in
    parts, from where it stands up to step ``k_to`` (a learning environment's policy period)."""
    a, st, view, timeline, trace = session.setup, session.loop, session.view, session.timeline, session.trace
    sch, backend, safety, controller = a.schedule, a.backend, session.safety, a.controller
    n, dof, dt, sub = sch.steps, a.robot.model.dof, sch.control_dt, sch.substeps
    k_from, k_end = st.k, n if k_to is None else min(k_to, n)
    ref_q, ref_qd, ref_qdd = session.ref.views()
    state, compute, check = backend.state, controller.compute, safety.check_row
    command, step = backend.command, backend.step
    # joints on their own servo loops (CSP/CSV drives) get the reference as the safety layer lets it through
    follow = backend.follow if isinstance(backend, FollowsReference) and backend.follows else None
    target = safety.target
    contacts = backend.contacts if isinstance(backend, Contacts) else list  # no contacts reported: none counted
    tq, tqd, ttau, packed = trace.q, trace.qd, trace.tau, session.packed  # column views of ``packed``
    record = a.space.recorder(trace, backend)  # what the reference's space records beside the joints
    log, log_every = view.log, sch.log_every
    taps = session.taps  # (extensions' taps see the logged steps too, logged or not)
    next_log = (0 if view.active or taps else -1) if st.next_log is None else st.next_log
    deferred_log = view.active and backend.realtime
    if deferred_log:
        log.deferred = True
    person = a.patient.torque if a.patient is not None else None
    late = int(round(a.patient.delay_s / dt)) if person else 0  # the person sees the cue this many steps late
    # a person at the joints is pushed through the backend; an embodied one acts through its straps in the scene
    push = backend.external_torque if person is not None and not isinstance(a.patient, EmbodiedPatient) else None
    tau_h, force_at, goal_at, f_h = trace.tau_h, a.force_source, session.ref.goal_at, trace.f_h  # (f_h: measured)
    stop_after = a.sc.safety.stop_after_s
    bar = _Progress(n) if progress else None
    # everything built so far lives for the whole run: frozen, the collector no longer walks it in the loop
    # (a full collection first would cost ~0.1 s of every run's start: only the youngest generation is swept)
    gc.collect(0)
    gc.freeze()
    contact_steps, due, k = st.contact_steps, st.due, k_from
    if st.failed:
        compute = _idle(dof)
    t_loop = time.perf_counter()
    try:
        for k in range(k_from, k_end):
            t = k * dt
            _, q, qd = state()
            if k >= due:
                due, replans = timeline.due(k, t, q, qd)
                if replans:
                    session.act(k, t, q, qd, replans)
                    due = k + 1 if due >= 0 else due  # (a new plan may have scene actions due at once)
                if due < 0:
                    st.stopped = True
                    break
            tq[k], tqd[k] = q, qd  # the row's columns, written one by one: cheaper than a concatenation
            out = NOTHING
            try:
                out = compute(t, q, qd, ref_q[k], ref_qd[k], ref_qdd[k])
                ttau[k] = out
            except Exception as exc:  # a crashing controller must still leave the robot held
                said, data = plugin_fault(a.registry, "controller", a.sc.controller.type, exc, out, dof)
                safety.trip(t, q, "plugin-error", said, qd, data=data)
                compute, st.failed, ttau[k] = _idle(dof), True, 0.0  # the safety layer drives from now on
            if person is not None:
                tau_h[k] = person(t, q, qd, goal_at[max(0, k - late)])
            if force_at is not None:
                session.force = force = force_at(t, q, tau_h[k] if person is not None else None)
                if f_h is not None:
                    f_h[k] = math.sqrt(force @ force)
                safety.check_force(t, q, force, qd)
            tau = check(t, packed[k])
            if follow is not None:
                follow(*target(t, ref_q[k], ref_qd[k], q))
            if record is not None:
                record(k, q)
            try:
                command(tau)
                if push is not None:
                    push(tau_h[k])
                step(sub)
            except BackendFaultError as exc:  # the robot can't be driven any more: stop, logs complete
                # (its cause as fields too: a bridge's hold, a lost state, an unanswered tick, a drive's fault)
                safety.trip(t, q, "backend", str(exc), qd, breach=exc.breach, data=exc.event_data())
                if not exc.observable:  # (else watched while the robot side stops it, as any safety stop)
                    k += 1
                    st.stopped = True
                    break
            if touching := contacts():
                if not contact_steps:  # the first one kept and said: what touched what, and where (a count alone
                    st.first_contact = first_contact(t, touching[0])  # left a speed trip after a hit unexplained)
                    view.event(t, st.first_contact["text"], level="WARN")
                contact_steps += 1
            if k == next_log:
                next_log += log_every
                view.record_step(t, k, q, trace)
                if taps:
                    with signals_deferred():  # (a tap's write whole: a Ctrl-C taken after it)
                        for tap in taps:
                            tap.logged(t, k)
            if deferred_log and log.queued:  # wall-clock run: one entity's columns a tick
                log.send_one()
            if bar is not None and k % 1000 == 999:
                bar.tick(k, t_loop)
            if safety.tripped_at is not None and _stopped(st, safety, backend, t, dt, stop_after):
                k += 1
                break
        else:
            k = k_end
    finally:
        st.k, st.due, st.contact_steps, st.next_log = k, due, contact_steps, next_log
        gc.unfreeze()
        if bar is not None:
            bar.close()
    return LoopResult(k, time.perf_counter() - t_loop, contact_steps, t_loop)


def bring_to_rest(session: RunSession, rule: str, message: str, data: dict | None = None) -> None:
    """End a run that was cut short (Ctrl-C, SIGTERM, a plugin's error out of the loop) as a safety stop ends one: the
    safety layer trips with ``rule`` (its stop category) and drives the robot — the controller, the person and the
    recording left out — until the stop has run its course, or the run's end. A backend that can't be driven any more
    ends it there."""
    a, st, safety, backend = session.setup, session.loop, session.safety, session.setup.backend
    sch = a.schedule
    dt, n, dof = sch.control_dt, sch.steps, a.robot.model.dof
    trace, packed = session.trace, session.packed
    record = a.space.recorder(trace, backend)  # (the hand where a Cartesian reference's space tracks it)
    k = min(st.k, n)
    try:
        _, q, qd = backend.state()
        if safety.tripped_at is None:
            safety.trip(k * dt, q, rule, message, qd, data=data)
        while k < n:
            t = k * dt
            _, q, qd = backend.state()
            trace.q[k], trace.qd[k] = q, qd
            if record is not None:
                record(k, q)
            packed[k, 2 * dof :] = 0.0  # (tripped: the layer sends its stop's torque whatever the row holds)
            backend.command(safety.check_row(t, packed[k]))
            backend.step(sch.substeps)
            k += 1
            if _stopped(st, safety, backend, t, dt, a.sc.safety.stop_after_s):
                break
    except BackendFaultError as exc:  # (the robot side stops it on its own: its watchdogs)
        if safety.tripped_at is None:
            safety.trip(k * dt, trace.q[max(k - 1, 0)], "backend", str(exc), data=exc.event_data())
    except Exception:  # noqa: BLE001 (what failed the run fails the stop too: the backend's close releases the robot)
        logging.getLogger(__name__).warning("the robot could not be brought to rest through the loop", exc_info=True)
    finally:
        st.k, st.stopped = k, True
