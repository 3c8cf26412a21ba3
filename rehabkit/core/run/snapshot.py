"""A run session taken at a step and put back: what a learning environment's reset and a forked replay stand on.

A :class:`SessionSnapshot` holds everything a run changes (:mod:`rehabkit.core.run.session`): where the loop stands,
the trace up to that step, the reference, the timeline, the plans and notes, the safety layer's state, the
backend's (a simulation's ``MjData`` among it; a robot's backend refuses, :class:`~rehabkit.core.kinds.backend.
NotRestorableError`) and each plugin's (``run_state()``, :mod:`rehabkit.core.kinds.run_state`). The Assembly is not
in it: it does not change while a run goes.

:func:`restore` puts a snapshot back into the session it was taken from — or into another session of the same
scenario with other settings (a fork): there a plugin whose settings changed starts afresh, and the scene must be the
same one (the same backend settings and model). A session being recorded takes a snapshot only while it stands at
its start: its recording then holds the run from the snapshot's step on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rehabkit.core.kinds.run_state import capture, translating
from rehabkit.core.kinds.run_state import restore as restore_state
from rehabkit.core.run.session import RunSession

__all__ = ["SessionSnapshot", "SnapshotMismatchError", "restore", "snapshot"]


class SnapshotMismatchError(ValueError):
    """The snapshot can't be put back into this session: said why (``part``: what differs)."""

    def __init__(self, part: str, why: str):
        super().__init__(f"{part}: {why}")
        self.part, self.why = part, why


@dataclass(frozen=True)
class SessionSnapshot:
    """A session's state at step ``k`` (see the module docstring); ``plugins`` by role, each with its settings;
    ``trace`` the trace's arrays whole."""

    k: int
    loop: dict
    trace: dict[str, np.ndarray]
    session: dict
    reference: dict
    gate: dict
    timeline: dict
    safety: Any
    backend: Any
    backend_settings: dict
    plugins: dict[str, tuple[dict, Any]] = field(default_factory=dict)
    parts: dict[str, Any] = field(default_factory=dict)  # the run's parts, to point references at a fork's
    # the settings objects themselves, by role ('backend' too): a session restored into itself (a learning
    # environment's reset) has the very same ones — the Assembly does not change while a run goes — and is not
    # compared field by field (a dump of every plugin's settings: ~1.2 ms of a ~6 ms reset on hit_myoarm)
    configs: dict[str, Any] = field(default_factory=dict)


def _plugins(s: RunSession) -> dict[str, tuple[Any, Any]]:
    """The session's plugins that run (the robot describes, and is the Assembly's), by role, with their settings."""
    a, sc = s.setup, s.setup.sc
    out = {"planner": (a.planner, sc.planner), "controller": (a.controller, sc.controller)}
    out.update({f"planner@{i}": (p, sc.task.events[i].planner) for i, p in a.event_planners.items()})
    out.update({f"sensor:{name}": (sensor, sc.sensors[name]) for name, sensor in a.sensors.items()})
    if a.patient is not None:
        out["patient"] = (a.patient, a.patient_slot.config if a.patient_slot is not None else None)
    return out


def _parts(s: RunSession) -> dict[str, Any]:
    """The parts of a run a plugin's state may refer to, by what they are."""
    a = s.setup
    out = {"setup": a, "robot": a.robot, "model": a.robot.model, "backend": a.backend, "context": a.context,
           "space": a.space, "force_source": a.force_source, "safety_setup": a.safety, "safety": s.safety,
           "session": s, "registry": a.registry, "schedule": a.schedule}
    # a simulation's scene (an embodied patient's body is bound to it)
    out.update({f"scene_{name}": getattr(a.backend, name, None) for name in ("model", "data")})
    out.update({role: plugin for role, (plugin, _) in _plugins(s).items()})
    return {name: part for name, part in out.items() if part is not None}


def _settings(config: Any) -> Any:
    return config.model_dump(mode="json") if hasattr(config, "model_dump") else config


def _same_settings(snap: SessionSnapshot, role: str, config: Any, dumped: Any) -> bool:
    """Whether ``config`` (the session's, for ``role``) is the snapshot's ``dumped`` settings: the same object, or
    equal field by field (a fork's, made again from its scenario)."""
    return snap.configs.get(role, _NONE) is config or _settings(config) == dumped


_NONE = object()  # (no settings object taken: a snapshot made elsewhere)


def snapshot(s: RunSession) -> SessionSnapshot:
    """The session as it stands (between two steps of :func:`~rehabkit.core.run.loop.run_loop`).

    Raises:
        NotRestorableError: the backend drives a robot.
    """
    a, k = s.setup, s.loop.k
    backend = a.backend.run_state()  # (first: a robot's backend refuses before anything is copied)
    # (whole: a step not run yet may be read before it is written — an observation of the step before the first)
    trace = {name: value.copy() for name, value in vars(s.trace).items() if isinstance(value, np.ndarray)}
    return SessionSnapshot(
        k, capture(s.loop), trace, capture(s),
        capture(s.ref), capture(s.gate), capture(s.timeline), s.safety.run_state(), backend,
        _settings(a.sc.backend),
        {role: (_settings(config), plugin.run_state()) for role, (plugin, config) in _plugins(s).items()},
        _parts(s), {"backend": a.sc.backend, **{role: config for role, (_, config) in _plugins(s).items()}})


def restore(s: RunSession, snap: SessionSnapshot) -> list[str]:
    """Put ``snap`` back into session ``s`` (its own, or a fork's: the module docstring); returns the roles of the
    plugins that start afresh (their settings differ from the snapshot's).

    Raises:
        SnapshotMismatchError: the scene differs, or the session records what can't be rewound (a recording, a tap).
    """
    a = s.setup
    if (s.view.active or s.taps) and s.loop.k != 0:
        raise SnapshotMismatchError("session", "it is being recorded (a Rerun recording or an extension's tap) and has "
                                    "run: what was written can't be taken back; restore into a session at its start "
                                    "(its recording then holds the run from the snapshot's step on)")
    if not _same_settings(snap, "backend", a.sc.backend, snap.backend_settings):
        raise SnapshotMismatchError("backend", "its settings differ from the snapshot's: the scene must be the same")
    if len(s.trace.t) != len(snap.trace["t"]):
        raise SnapshotMismatchError("duration", f"the session is {len(s.trace.t)} steps long, the snapshot's "
                                    f"{len(snap.trace['t'])}: fork with the same duration")
    here = _parts(s)
    with translating({id(part): here[name] for name, part in snap.parts.items() if name in here}):
        return _restore(s, snap)


def _restore(s: RunSession, snap: SessionSnapshot) -> list[str]:
    a = s.setup
    a.backend.restore_run_state(snap.backend)
    fresh = []
    for role, (plugin, config) in _plugins(s).items():
        taken = snap.plugins.get(role)
        if taken is None or not _same_settings(snap, role, config, taken[0]):
            fresh.append(role)
            continue
        plugin.restore_run_state(taken[1])
    s.safety.restore_run_state(snap.safety)
    restore_state(s.loop, snap.loop)
    # logged from the snapshot's step on where this session is recorded (the snapshot's run may not have been)
    every = a.schedule.log_every
    s.loop.next_log = -(-snap.k // every) * every if s.view.active or s.taps else -1
    for name, rows in snap.trace.items():
        value = getattr(s.trace, name, None)
        if isinstance(value, np.ndarray) and value.shape == rows.shape:
            value[...] = rows
    restore_state(s, snap.session)
    restore_state(s.ref, snap.reference)
    restore_state(s.gate, snap.gate)
    restore_state(s.timeline, snap.timeline)
    return fresh
