"""The person in a run and the safety layer that guards them: the simulated patient plugin's slot (a layer's section
holding its settings), the patient built where the backend can host them, the interaction-force source and limit,
and the :class:`~rehabkit.core.safety.layer.SafetySetup` each run's safety layer is made from — step 5 of
:mod:`rehabkit.core.setup.assembly`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rehabkit.core.kinds.capabilities import ExternalTorques, HostsBodies
from rehabkit.core.kinds.interfaces import EmbodiedPatient
from rehabkit.core.plugins.lifecycle import Extensions
from rehabkit.core.plugins.registry import PluginRegistry
from rehabkit.core.safety.layer import SafetySetup
from rehabkit.core.setup.checks import has
from rehabkit.core.setup.errors import PluginSetupError
from rehabkit.core.setup.force_source import check_reaction, force_source
from rehabkit.models.hand_force import hand_in_world


@dataclass(frozen=True)
class PatientSlot:
    """Where a layer's section holds the simulated patient plugin's settings (the rehab layer's ``patient.model``):
    the section's value, the settings (None: no simulated person) and their key path."""

    section: Any
    config: Any
    path: tuple[str, str]


def patient_slot(sc, registry: PluginRegistry, extensions: Extensions) -> PatientSlot | None:
    """The scenario's patient plugin slot, when a layer declares one and the scenario fills its section."""
    for (name, key), kind in extensions.plugin_slots(registry).items():
        section = getattr(sc, name, None)  # (a field of the scenario's model, from the same extensions)
        if kind == "patient" and section is not None:
            return PatientSlot(section, getattr(section, key, None), (name, key))
    return None


def person_and_safety(a) -> None:
    """The simulated person (where a layer's slot names one and the backend can host them), the run's interaction-force
    source and limit (the envelope's and the extensions'), and the safety layer guarding both, on ``a`` (the run's
    :class:`~rehabkit.core.setup.assembly.Assembly`, its robot, sensors and controller built)."""
    sc, slot = a.sc, a.patient_slot
    info = a.registry.get("backend", sc.backend.type)
    backend = a.backend if a.backend is not None else info.factory  # (validate builds no backend: its class)
    real_person = info.declared.real_person
    model_cfg = slot.config if slot is not None else None
    if model_cfg is not None:
        where = ".".join(slot.path)
        if real_person:
            if a.context.note is not None:
                a.context.note(0.0, f"{where} '{model_cfg.type}' is not simulated on the '{sc.backend.type}' "
                                    "backend: the person is real")
        else:
            factory = a.registry.get("patient", model_cfg.type).factory
            embodied = isinstance(factory, type) and issubclass(factory, EmbodiedPatient)
            need, what = (HostsBodies, "simulates a person's body in its scene") if embodied else \
                (ExternalTorques, "applies a simulated person's torques")
            if not has(backend, need):
                raise PluginSetupError(a.loaded.source, (*slot.path, "type"),
                                       f"{where} '{model_cfg.type}' needs a backend that {what}; backend "
                                       f"'{sc.backend.type}' does not")
            a.patient = a.make("patient", model_cfg, slot.path)
    limits = [v for v in (sc.safety.interaction_force_n, *a.extensions.hook.rehabkit_force_limit(scenario=sc))
              if v is not None]
    force_limit = min(limits) if limits else None
    a.force_source = force_source(a, force_limit)
    check_reaction(a, force_limit)
    source = a.force_source
    a.safety = SafetySetup(a.robot.model, sc.safety.model_copy(update={"interaction_force_n": force_limit}),
                           gravity=a.robot.gravity_torque, dt=a.context.control_dt,
                           hand=hand_in_world(a.robot) if sc.safety.keep_in is not None else None,
                           joint_torque=source.joint_torque if source is not None else None,
                           push_torque=source.push_torque if source is not None else None)
    off = sorted(r for r, c in a.safety.categories.items() if c < 2 and r in sc.safety.stop_category)
    if off and a.robot.model.brakes is None and a.context.note is not None:
        a.context.note(0.0, f"stop category 0/1 for {', '.join(off)}: the torque goes off, and robot "
                            f"'{a.robot.model.name}' has no brakes: after such a stop it is free to move (its weight, "
                            "the person)")
