"""Where a run's interaction force comes from, chosen once at setup.

The safety envelope checks the force between person and robot every control step; a controller reads the
value checked last (``Context.interaction_force()``, the run session's). The source is measured — force-torque
sensors on any backend that reads them, or an embodied person's straps in the simulated scene — or estimated at
the hand from a simulated person's joint torques. An interaction-force limit with no source is refused at the setting.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable

import numpy as np

from rehabkit.core.kinds.interfaces import EmbodiedPatient, InteractionForceSensor
from rehabkit.core.setup.errors import PluginSetupError
from rehabkit.models.hand_force import HandForce

Read = Callable[[float, np.ndarray, "np.ndarray | None"], np.ndarray]


class ForceSource:
    """``source(t, q, tau_person)`` → the interaction force [N] (3 values, world frame); ``measured`` whether it is
    measured or estimated. The value a run checked last is its session's (``RunSession.force``)."""

    def __init__(self, read: Read, measured: bool,
                 joint_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None,
                 push_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None):
        self._read, self.measured = read, measured
        self.joint_torque = joint_torque  # (q, force) -> the joint torques it exerts, where known
        # (q, force) -> the joint torques of the whole interaction now (several straps: all of them); default the above
        self.push_torque = push_torque or joint_torque

    def __call__(self, t: float, q: np.ndarray, tau_h: np.ndarray | None) -> np.ndarray:
        return self._read(t, q, tau_h)


def force_source(a, limit: float | None) -> ForceSource | None:
    """The source of the run's interaction force (``a``: the run's :class:`~rehabkit.core.setup.assembly.Assembly`,
    its sensors, patient and backend built or about to be): force-torque sensors (the largest of several: a cuff per
    segment), else an embodied person's straps, else a simulated person's torques where a limit needs them."""
    sensing = [s for s in a.sensors.values() if isinstance(s, InteractionForceSensor) and s.interaction]
    # the backend is built after the source, and the assembly holds the source: reached weakly, as a strong
    # reference would be a cycle keeping the run (its MuJoCo scene) alive until a full collection
    setup = weakref.ref(a)
    if len(sensing) == 1:  # (the common case: no list and max each control step)
        sensor = sensing[0]
        return ForceSource(lambda t, q, tau_h: sensor.interaction_force(t, setup().backend), True, sensor.joint_torque)
    if sensing:
        seen: list[np.ndarray] = []

        def largest(t, q, tau_h):
            backend = setup().backend
            seen[:] = [s.interaction_force(t, backend) for s in sensing]
            return max(seen, key=lambda f: f @ f)

        def all_torques(q, force):  # every sensor's force, each where it acts
            torques = [s.joint_torque(q, f) for s, f in zip(sensing, seen)]
            return None if not seen or any(x is None for x in torques) else np.sum(torques, axis=0)
        return ForceSource(largest, True, all_torques)
    if isinstance(a.patient, EmbodiedPatient):
        person = a.patient
        return ForceSource(lambda t, q, tau_h: person.interaction_force(), True, person.joint_torque,
                           lambda q, f: person.interaction_torque())
    if a.patient is not None and limit is not None:
        estimate = HandForce(a.robot.model)
        return ForceSource(lambda t, q, tau_h: estimate(q, tau_h), False, lambda q, f: estimate.jacobian(q).T @ f)
    if limit is not None:
        at = ("safety", "interaction_force_n") if a.sc.safety.interaction_force_n is not None else \
            (a.patient_slot.path[:1] if a.patient_slot is not None else ())
        raise PluginSetupError(a.loaded.source, at,
                               f"an interaction-force limit ({limit:g} N, from safety.interaction_force_n or "
                               "patient.comfort) needs a source of the force: a force-torque sensor (sensors: {ft: "
                               "{type: force-torque}}) or a simulated patient (patient.model); backend "
                               f"'{a.sc.backend.type}' measures none")
    return None


def check_reaction(a, limit: float | None) -> None:
    """A force-limiting reaction (``safety.reactions``) needs a force limit, and a retreat a release below it and a
    source whose force's point of action is known (its direction in the joints); ``a``: the run's assembly, its force
    source chosen."""
    reaction = a.sc.safety.reactions.get("interaction-force")
    if reaction is None or reaction.type == "stop":
        return
    at = ("safety", "reactions", "interaction-force")
    if limit is None:
        raise PluginSetupError(a.loaded.source, (*at, "type"), f"a '{reaction.type}' reaction needs an "
                               "interaction-force limit: set safety.interaction_force_n (or the patient's comfort)")
    if reaction.type != "retreat":
        return
    if reaction.release_n is not None and reaction.release_n >= limit:
        raise PluginSetupError(a.loaded.source, (*at, "release_n"), f"release_n ({reaction.release_n:g} N) must "
                               f"be below the run's force limit ({limit:g} N): the retreat ends below it")
    if a.force_source is None or a.force_source.joint_torque is None:
        raise PluginSetupError(a.loaded.source, (*at, "type"), "a retreat moves along the force, so it needs to "
                               "know where on the robot the force acts: a force-torque sensor (sensors: {ft: {type: "
                               "force-torque}}) or a simulated patient; this run's force source does not say "
                               "(use yield)")
