"""What :func:`rehabkit.core.setup.assembly.assemble` checks before anything runs, each refusal located in the scenario
file: the capabilities plugins need, names the scene already uses, a test rig's loads, a duration that fits in memory,
joint targets within the ranges in force."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from rehabkit.core.kinds.capabilities import SceneObjects, in_words, lacking
from rehabkit.core.kinds.errors import apart
from rehabkit.core.kinds.interfaces import PlanningError
from rehabkit.core.kinds.metric import CORE_METRICS, MetricCatalogue
from rehabkit.core.kinds.names import nearest
from rehabkit.core.scenario.errors import Diagnostic, ScenarioError
from rehabkit.core.setup.errors import PluginSetupError, SetupError
from rehabkit.models.robot_model import RobotModel
from rehabkit.models.strict import SENSOR_SETTING, marked_settings

Assembly = Any  # a rehabkit.core.setup.assembly.Assembly (which imports this module: no import back)


def check_capabilities(a: Assembly) -> None:
    """Plugins that need something of the robot or the backend (a workspace table, a floating base, cameras, …)
    say so up front; so does the task (a simulated person, objects moved by events)."""
    sc = a.sc
    backend = a.registry.get("backend", sc.backend.type).factory  # checked on the class: not built yet
    named = [("planner", sc.planner), ("controller", sc.controller), *(("sensor", c) for c in sc.sensors.values())]
    paths = {"planner": ("planner", "type"), "controller": ("controller", "type")}
    problems, at, lacked = [], None, {}
    for kind, cfg in named:
        lack = lacking(a.registry.get(kind, cfg.type).declared.requires, a.robot, backend)
        if lack:
            problems.append(f"{kind} '{cfg.type}' needs {' and '.join(in_words(lack))}")
            lacked[(kind, cfg.type)] = tuple(lack)
            section = paths.get(kind) or ("sensors", next(n for n, c in sc.sensors.items() if c is cfg), "type")
            at = at or section
    if any(e.action == "move" for e in sc.task.events) and not has(backend, SceneObjects):
        problems.append("task events that 'move' objects need a backend with scene objects")
        lacked[("task", "events")] = (SceneObjects,)
        at = at or ("backend",)
    if problems:
        refused = PluginSetupError(a.loaded.source, at, f"{'; '.join(problems)} (robot '{sc.robot.type}', "
                                   f"backend '{sc.backend.type}')")
        refused.missing = lacked  # (what it says, as fields)
        raise refused


SCENE_NAMES = ("floor", "key_light")  # what the scene adds besides the robot and the world's objects


def check_scene_names(a: Assembly) -> None:
    """A world object or camera may not take a name the scene already uses (MuJoCo would refuse the merged scene,
    pointing into XML the user never wrote)."""
    import xml.etree.ElementTree as ET

    robot = {e.get("name"): e.tag for e in ET.fromstring(a.robot.model.mjcf).iter() if e.get("name")}
    for kind, items in (("objects", a.sc.world.objects), ("cameras", a.sc.world.cameras)):
        for i, item in enumerate(items):
            owner = "rehabkit's scene" if item.name in SCENE_NAMES else (
                f"the robot's {robot[item.name]}" if item.name in robot else None)
            if owner:
                raise PluginSetupError(a.loaded.source, ("world", kind, i, "name"),
                                       f"world.{kind}: the name '{item.name}' is taken by {owner}", fix="rename it")


def scene_bodies(a: Assembly) -> list[str]:
    """The bodies of the run's scene: the robot's, the world's objects, the sensors' mounts."""
    import xml.etree.ElementTree as ET

    bodies = [e.get("name") for e in ET.fromstring(a.robot.model.mjcf).iter("body") if e.get("name")]
    bodies += [o.name for o in a.sc.world.objects if o.dynamic or o.mocap]
    return bodies + sorted({i.mount for i in a.context.instruments if i.mount})


def check_loads(a: Assembly) -> None:
    """A test rig's load pushes on a robot body or a force sensor's mount, and a sensor's instruments sit on a body
    of the scene: another name is refused where written."""
    bodies = scene_bodies(a)
    for name, sensor in a.sensors.items():
        for ins in sensor.instruments():
            if ins.body not in bodies:
                cfg = a.sc.sensors[name]
                at = ("sensors", name, "body") if getattr(cfg, "body", None) == ins.body else ("sensors", name)
                raise PluginSetupError(a.loaded.source, at, f"sensor '{name}': no body '{ins.body}' in the scene",
                                       fix=nearest(ins.body, bodies))
    for i, load in enumerate(a.sc.world.loads):
        if load.body not in bodies:
            said, fix = misnamed(f"world.loads '{load.name}': no body '{load.body}' in the scene", load.body, bodies,
                                 " (a robot body, or a force-torque sensor's name)")
            raise PluginSetupError(a.loaded.source, ("world", "loads", i, "body"), said, fix=fix)


def check_duration(a: Assembly) -> None:
    """A run records every control step (about 8 rows of the robot's joints, 8-byte numbers): refuse, located, a
    duration whose record would not fit in half this machine's memory (``duration: 1e9`` ended in MemoryError)."""
    sc = a.sc
    steps = sc.duration * sc.rates.control_hz
    need = steps * (8 * a.robot.model.dof + 4) * 8
    have = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if need > have / 2:
        mark = a.loaded.source.key_marks.get(("duration",), a.loaded.source.value_marks[()])
        raise ScenarioError([Diagnostic(mark, "duration", f"{sc.duration:g} s at {sc.rates.control_hz:g} Hz is "
                            f"{steps:.3g} control steps, whose record needs ~{need / 2**30:.3g} GiB (this machine has "
                            f"{have / 2**30:.3g} GiB)", "shorten the run or split it")])


def misnamed(said: str, name: str, candidates, then: str = "") -> tuple[str, str]:
    """A misnamed thing's message and fix (the names nearest ``name``), ``then`` said after both (after the message
    where no name is near): a diagnostic's ``message`` and ``fix``, read as they always were."""
    fix = nearest(name, candidates)
    return (said, fix + then) if fix else (said + then, "")


def has(backend: Any, capability: type) -> bool:
    return issubclass(backend, capability) if isinstance(backend, type) else isinstance(backend, capability)


def check_joint_targets(a: Assembly) -> None:
    """Joint values a target gives within the joint ranges in force (after a patient's admission)."""
    from rehabkit.core.safety.limit_breach import first_breach

    model = a.robot.model
    for name, target in a.targets.items():
        if target.q is None:
            continue
        breach = first_breach(model.limits, model.joint_names, target.q[None], None, np.zeros(1),
                              revolute=model.revolute)
        if breach is not None:
            said = f"target '{name}': its joint values put {breach.describe()}"
            why = PlanningError(said, target=name, fix=target.hint or "")
            refused = at_target(a, why, "task") or SetupError(said, fix=why.fix)
            refused.breach = breach  # (what it says, as fields: as a first plan's refusal carries its breach)
            raise refused


def at_target(a: Assembly, exc: Exception, kind: str = "planner") -> PluginSetupError | None:
    """A refusal about one target (out of reach, say: a :class:`PlanningError` naming it), located at where that
    target is given."""
    target = exc.target if isinstance(exc, PlanningError) else None
    index = next((i for i, t in enumerate(a.sc.task.targets) if target is not None and t.name == target), None)
    if index is None:
        return None
    spec = a.sc.task.targets[index]
    key = next(k for k in ("position", "joints_deg", "joints_rad", "joints", "same_as", "random", "sensor")
               if getattr(spec, k) is not None)
    prefix = f"planner '{a.sc.planner.type}': " if kind == "planner" else ""
    text, fix = apart(exc)
    return PluginSetupError(a.loaded.source, ("task", "targets", index, key), f"{prefix}{text}", fix=fix)


def check_sensor_settings(a: Assembly) -> None:
    """Settings naming a sensor (:data:`~rehabkit.models.strict.SensorName`) in the planner's, the controller's and
    the patient model's sections name one of the scenario's sensors: another is refused at the setting."""
    sections = [(("planner",), a.sc.planner), (("controller",), a.sc.controller)]
    if a.patient_slot is not None and a.patient_slot.config is not None:
        sections.append((a.patient_slot.path, a.patient_slot.config))
    for path, config in sections:
        for loc, name in marked_settings(config, SENSOR_SETTING, path):
            if name not in a.sc.sensors:
                have = ", ".join(a.sc.sensors) or "none"
                said, fix = misnamed(f"no sensor '{name}' in this scenario", name, a.sc.sensors,
                                     f" (its sensors: {have})")
                raise PluginSetupError(a.loaded.source, loc, said, fix=fix)


def metric_catalogue(a: Assembly) -> MetricCatalogue:
    """Every metric the run can report, described: the core's, the extensions', each plugin's."""
    catalogue = MetricCatalogue(CORE_METRICS)
    catalogue.add(a.extensions.metrics())
    for plugin in (a.planner, a.controller, a.patient, *a.sensors.values()):
        catalogue.add(plugin.metrics if plugin is not None else ())
    catalogue.add(a.registry.get("backend", a.sc.backend.type).declared.metrics)  # (validate builds no backend)
    return catalogue


def check_expectations(a: Assembly) -> None:
    """An ``expect:`` on a metric nothing in this run reports could never be met: refused, with the nearest."""
    catalogue = a.catalogue if a.catalogue is not None else metric_catalogue(a)
    for name in a.sc.expect:
        if not catalogue.known(name):
            said, fix = misnamed(f"expect: no plugin of this run reports a metric '{name}'", name, catalogue.names(),
                                 " (see `rehabkit plugins` for each plugin's)")
            raise PluginSetupError(a.loaded.source, ("expect", name), said, fix=fix)


def check_robot_model(a: Assembly) -> None:
    """A robot plugin's constructor sets ``self.model`` to its :class:`RobotModel`: said at its type if it did not."""
    try:
        model = a.robot.model
    except AttributeError:
        model = None
    if not isinstance(model, RobotModel):
        raise PluginSetupError(a.loaded.source, ("robot", "type"),
                               f"robot '{a.sc.robot.type}' set no self.model in its constructor (a RobotModel: its "
                               "name, MJCF, joint names, limits and end-effector site)")
