"""Putting a run together: robot, limits, plugins, safety layer, targets.

One function, :func:`assemble`, for ``rehabkit run`` and ``rehabkit validate``: the
latter builds everything but the backend (``upto="plugins"``, a dry-run context) and
then makes the first plan (:func:`check_first_plan`), and so refuses what a run's
setup would. The order:

1. extensions adapt the robot's settings (``rehabkit_configure_robot``); the robot is built;
2. its limits are narrowed by the envelope and the extensions (``rehabkit_narrow_limits``)
   and set on the model, so everything built after plans and checks within them;
3. the robot's declared capabilities are checked against what the other plugins require;
4. targets are resolved and admitted (``rehabkit_admit_targets``);
5. sensors, planner, controller, patient, the interaction-force limit (``rehabkit_force_limit``), the safety
   layer, and the backend last (its scene holds the sensors' instruments and an embodied patient's body).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from rehabkit.core.capabilities import ExternalTorques, HostsBodies, SceneObjects, missing_capabilities
from rehabkit.core.errors import PluginSetupError, SetupError
from rehabkit.core.interfaces import (
    Backend,
    Context,
    Controller,
    EmbodiedPatient,
    InteractionForceSensor,
    Patient,
    Planner,
    PlanningError,
    PlanRequest,
    Robot,
    Sensor,
    Target,
)
from rehabkit.core.lifecycle import Extensions
from rehabkit.core.limits import LimitSources, envelope_narrowings, narrow, unknown_joint
from rehabkit.core.metric import CORE_METRICS, MetricCatalogue
from rehabkit.core.names import suggest
from rehabkit.core.plugins import PluginRegistry
from rehabkit.core.safety import SafetyLayer
from rehabkit.core.scenario.errors import Diagnostic, ScenarioError
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.targets import resolve_targets
from rehabkit.models.hand_force import HandForce, hand_in_world
from rehabkit.models.robot_model import JointLimits

REACH_CHECK_HZ = 100.0  # 'reached' events are tested at this rate, not every control step


@dataclass(frozen=True)
class Schedule:
    """The loop's timing, in control steps."""

    control_dt: float
    substeps: int
    steps: int
    log_every: int
    reach_every: int
    sensor_every: tuple[int, ...]


@dataclass
class Assembly:
    """Everything a run is made of, built by :func:`assemble` (fields after ``robot`` only with ``upto="run"``).

    ``robot_limits`` are the robot's own, ``limits`` the run's (narrowed; also set on ``robot.model``),
    ``limit_sources`` who narrowed what. ``sections`` collects what extensions say for ``summary.json``,
    ``extras`` what they keep between hooks.
    """

    loaded: LoadedScenario
    registry: PluginRegistry
    extensions: Extensions
    out_dir: Path | None
    robot_config: Any
    context: Context
    robot: Robot | None = None
    robot_limits: JointLimits | None = None
    limits: JointLimits | None = None
    limit_sources: LimitSources = field(default_factory=LimitSources)
    targets: dict[str, Target] = field(default_factory=dict)
    replaced: list[dict] = field(default_factory=list)
    sections: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)  # extensions' own state between their hooks
    sensors: dict[str, Sensor] = field(default_factory=dict)
    backend: Backend | None = None
    planner: Planner | None = None
    event_planners: dict[int, Planner] = field(default_factory=dict)  # replan events with planner settings
    controller: Controller | None = None
    patient: Patient | None = None
    # the interaction force [N] each control step, (t, q, τ_person) → 3 values: measured (a force-torque sensor, an
    # embodied person's straps) or estimated from a simulated person's joint torques; ``measured`` says which
    force_source: Callable[[float, np.ndarray, np.ndarray | None], np.ndarray] | None = None
    force_measured: bool = False
    safety: SafetyLayer | None = None
    schedule: Schedule | None = None

    @property
    def sc(self):
        """The validated scenario."""
        return self.loaded.model

    def make(self, kind: str, config, path: tuple[str, ...]) -> Any:
        """Build plugin ``config.type`` of ``kind`` from the section at ``path``; its ``ValueError`` or
        ``PlanningError`` becomes a :class:`PluginSetupError` located in the scenario file."""
        info = self.registry.get(kind, config.type)
        try:
            return info.factory(config, self.context)
        except (ValueError, PlanningError) as exc:
            raise PluginSetupError.refused(self.loaded.source, path, kind, config, exc) from exc


def assemble(loaded: LoadedScenario, registry: PluginRegistry, extensions: Extensions, out_dir: Path | None = None,
             upto: Literal["targets", "plugins", "run"] = "run", plan: Callable | None = None,
             note: Callable[[float, str], None] | None = None) -> Assembly:
    """Build the run of ``loaded`` (see the module docstring); ``plan``/``note`` go to the controllers' context.

    Raises:
        ScenarioError: something the scenario got wrong, located in its file.
        SetupError: the plugins can't be put together as configured.
    """
    sc = loaded.model
    ctx = Context(loaded.directory, np.random.default_rng(sc.seed), 1.0 / sc.rates.control_hz, world=sc.world,
                  out_dir=out_dir, seed=sc.seed, safety=sc.safety, patient=sc.patient, plan=plan, note=note,
                  dry_run=upto != "run")
    a = Assembly(loaded, registry, extensions, out_dir, sc.robot, ctx)
    extensions.hook.rehabkit_configure_robot(setup=a)
    a.context = replace(ctx, robot_spec=a.robot_config.model_dump(mode="json"))
    a.robot = a.make("robot", a.robot_config, ("robot",))
    a.context = replace(a.context, robot=a.robot)
    _narrow_limits(a)
    _check_capabilities(a)
    _check_scene_names(a)
    try:
        a.targets = resolve_targets(sc.task, a.robot, sc.seed)
    except PlanningError as exc:
        raise _at_target(a, exc, "task") or SetupError(f"task: {exc}") from exc
    extensions.hook.rehabkit_admit_targets(setup=a)
    _check_joint_targets(a)
    _check_duration(a)
    if upto == "targets":
        return a
    # sensors before the backend: their instruments go into the scene it builds
    a.sensors = {name: a.make("sensor", cfg, ("sensors", name)) for name, cfg in sc.sensors.items()}
    a.context = replace(a.context, instruments=[i for s in a.sensors.values() for i in s.instruments()])
    _check_loads(a)
    a.planner = a.make("planner", sc.planner, ("planner",))
    for i, ev in enumerate(sc.task.events):
        if ev.planner is not None:  # (the settings were validated with the scenario, each located)
            config = type(sc.planner).model_validate({**sc.planner.model_dump(), **ev.planner})
            a.event_planners[i] = a.make("planner", config, ("task", "events", i, "planner"))
    a.context = replace(a.context, reference_space=a.planner.space)
    a.controller = a.make("controller", sc.controller, ("controller",))
    if a.planner.space != a.controller.reference:
        raise PluginSetupError(a.loaded.source, ("controller", "type"), (),
                               f"planner '{sc.planner.type}' plans in {a.planner.space} space but controller "
                               f"'{sc.controller.type}' takes {a.controller.reference} references; pick a "
                               "matching pair")
    for t in sc.task.targets:
        if t.sensor and t.sensor not in a.sensors:
            raise SetupError(f"target '{t.name}' follows sensor '{t.sensor}', which is not in 'sensors'"
                             f"{suggest(t.sensor, a.sensors)}")
    _patient_and_safety(a)
    if upto == "run":  # last: a backend may start processes (a hardware link's bridge); its scene holds the
        # sensors' instruments and an embodied patient's body
        bodies = (a.patient,) if isinstance(a.patient, EmbodiedPatient) else ()
        a.context = replace(a.context, bodies=bodies)
        a.backend = a.make("backend", sc.backend, ("backend",))
    _check_expectations(a)
    a.schedule = _schedule(a)
    return a


def metric_catalogue(a: Assembly) -> MetricCatalogue:
    """Every metric the run can report, described: the core's, the extensions', each plugin's."""
    catalogue = MetricCatalogue(CORE_METRICS)
    catalogue.add(a.extensions.metrics())
    backend = a.backend if a.backend is not None else a.registry.get("backend", a.sc.backend.type).factory
    for plugin in (a.planner, a.controller, backend, a.patient, *a.sensors.values()):
        catalogue.add(getattr(plugin, "metrics", ()) if plugin is not None else ())
    return catalogue


def _check_expectations(a: Assembly) -> None:
    """An ``expect:`` on a metric nothing in this run reports could never be met: refused, with the nearest."""
    catalogue = metric_catalogue(a)
    for name in a.sc.expect:
        if not catalogue.known(name):
            raise PluginSetupError(a.loaded.source, ("expect", name), (),
                                   f"expect: no plugin of this run reports a metric '{name}'"
                                   f"{suggest(name, catalogue.names())} (see `rehabkit plugins` for each plugin's)")


def _narrow_limits(a: Assembly) -> None:
    """Robot ∩ extensions ∩ envelope, set on the robot model; joint names the robot lacks refused where written."""
    sc, model, source = a.sc, a.robot.model, a.loaded.source
    problems = [Diagnostic(source.key_marks.get(("safety", "joints", n), source.value_marks[()]),
                           f"safety.joints.{n}", msg) for n in sc.safety.joints if (msg := unknown_joint(n, model))]
    try:
        asked = [nw for found in a.extensions.hook.rehabkit_narrow_limits(setup=a) for nw in found or ()]
    except ScenarioError as exc:  # every misnamed joint at once, the extensions' and the envelope's
        raise ScenarioError([*exc.diagnostics, *problems]) from None
    if problems:
        raise ScenarioError(problems)
    a.robot_limits = model.limits
    try:  # the extensions' first: a value both give is credited to the extension
        a.limits, a.limit_sources = narrow(model, [*asked, *envelope_narrowings(sc.safety)])
    except ValueError as exc:
        raise SetupError(str(exc)) from exc
    model.limits = a.limits


def _check_capabilities(a: Assembly) -> None:
    """Plugins that need something of the robot or the backend (a workspace table, a floating base, cameras, …)
    say so up front; so does the task (a simulated person, objects moved by events)."""
    sc = a.sc
    backend = a.registry.get("backend", sc.backend.type).factory  # checked on the class: not built yet
    named = [("planner", sc.planner), ("controller", sc.controller), *(("sensor", c) for c in sc.sensors.values())]
    paths = {"planner": ("planner", "type"), "controller": ("controller", "type")}
    problems, at = [], None
    for kind, cfg in named:
        missing = missing_capabilities(a.registry.get(kind, cfg.type).factory, a.robot, backend)
        if missing:
            problems.append(f"{kind} '{cfg.type}' needs {' and '.join(missing)}")
            section = paths.get(kind) or ("sensors", next(n for n, c in sc.sensors.items() if c is cfg), "type")
            at = at or section
    if any(e.action == "move" for e in sc.task.events) and not _has(backend, SceneObjects):
        problems.append("task events that 'move' objects need a backend with scene objects")
        at = at or ("backend",)
    if problems:
        raise PluginSetupError(a.loaded.source, at, (), f"{'; '.join(problems)} (robot '{sc.robot.type}', "
                               f"backend '{sc.backend.type}')")


SCENE_NAMES = ("floor", "key_light")  # what the scene adds besides the robot and the world's objects


def _check_scene_names(a: Assembly) -> None:
    """A world object or camera may not take a name the scene already uses (MuJoCo would refuse the merged scene,
    pointing into XML the user never wrote)."""
    import xml.etree.ElementTree as ET

    robot = {e.get("name"): e.tag for e in ET.fromstring(a.robot.model.mjcf).iter() if e.get("name")}
    for kind, items in (("objects", a.sc.world.objects), ("cameras", a.sc.world.cameras)):
        for i, item in enumerate(items):
            owner = "rehabkit's scene" if item.name in SCENE_NAMES else (
                f"the robot's {robot[item.name]}" if item.name in robot else None)
            if owner:
                raise PluginSetupError(a.loaded.source, ("world", kind, i, "name"), (),
                                       f"world.{kind}: the name '{item.name}' is taken by {owner}; rename it")


def _check_loads(a: Assembly) -> None:
    """A test rig's load pushes on a robot body or a force sensor's mount: another name is refused where written."""
    import xml.etree.ElementTree as ET

    bodies = [e.get("name") for e in ET.fromstring(a.robot.model.mjcf).iter("body") if e.get("name")]
    bodies += sorted({i.mount for i in a.context.instruments if i.mount})
    for i, load in enumerate(a.sc.world.loads):
        if load.body not in bodies:
            raise PluginSetupError(a.loaded.source, ("world", "loads", i, "body"), (),
                                   f"world.loads '{load.name}': no body '{load.body}' in the scene"
                                   f"{suggest(load.body, bodies)} (a robot body, or a force-torque sensor's name)")


def _check_duration(a: Assembly) -> None:
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
                            f"{have / 2**30:.3g} GiB); shorten the run or split it")])


def _has(backend: Any, capability: type) -> bool:
    return issubclass(backend, capability) if isinstance(backend, type) else isinstance(backend, capability)


def _patient_and_safety(a: Assembly) -> None:
    sc = a.sc
    backend = a.backend if a.backend is not None else a.registry.get("backend", sc.backend.type).factory
    model_cfg = getattr(sc.patient, "model", None) if sc.patient is not None else None
    if model_cfg is not None:
        if getattr(backend, "real_person", False):
            if a.context.note is not None:
                a.context.note(0.0, f"patient.model '{model_cfg.type}' is not simulated on the '{sc.backend.type}' "
                                    "backend: the person is real")
        else:
            factory = a.registry.get("patient", model_cfg.type).factory
            embodied = isinstance(factory, type) and issubclass(factory, EmbodiedPatient)
            need, what = (HostsBodies, "simulates a person's body in its scene") if embodied else \
                (ExternalTorques, "applies a simulated person's torques")
            if not _has(backend, need):
                raise PluginSetupError(a.loaded.source, ("patient", "model", "type"), (),
                                       f"patient.model '{model_cfg.type}' needs a backend that {what}; backend "
                                       f"'{sc.backend.type}' does not")
            a.patient = a.make("patient", model_cfg, ("patient", "model"))
    limits = [v for v in (sc.safety.interaction_force_n, *a.extensions.hook.rehabkit_force_limit(setup=a))
              if v is not None]
    force_limit = min(limits) if limits else None
    _force_source(a, force_limit)
    a.safety = SafetyLayer(a.robot.model, sc.safety.model_copy(update={"interaction_force_n": force_limit}),
                           gravity=a.robot.gravity_torque, dt=a.context.control_dt,
                           hand=hand_in_world(a.robot) if sc.safety.keep_in is not None else None)


def _force_source(a: Assembly, limit: float | None) -> None:
    """Where the interaction force comes from: force-torque sensors (measured, on any backend reading them), else an
    embodied person's straps (measured in the scene), else a simulated person's joint torques (estimated at the
    hand); an interaction-force limit with none of them is refused."""
    sensing = [s for s in a.sensors.values() if isinstance(s, InteractionForceSensor) and s.interaction]
    if sensing:
        def measured(t, q, tau_h):  # the largest of them (a cuff per segment)
            forces = [s.interaction_force(t, a.backend) for s in sensing]
            return max(forces, key=lambda f: f @ f)

        a.force_source, a.force_measured = measured, True
    elif isinstance(a.patient, EmbodiedPatient):
        a.force_source, a.force_measured = (lambda t, q, tau_h: a.patient.interaction_force()), True
    elif a.patient is not None and limit is not None:
        estimate = HandForce(a.robot.model)
        a.force_source = lambda t, q, tau_h: estimate(q, tau_h)
    elif limit is not None:
        at = ("safety", "interaction_force_n") if a.sc.safety.interaction_force_n is not None else ("patient",)
        raise PluginSetupError(a.loaded.source, at, (),
                               f"an interaction-force limit ({limit:g} N, from safety.interaction_force_n or "
                               "patient.comfort) needs a source of the force: a force-torque sensor (sensors: {ft: "
                               "{type: force-torque}}) or a simulated patient (patient.model); backend "
                               f"'{a.sc.backend.type}' measures none")


def _schedule(a: Assembly) -> Schedule:
    sc = a.sc
    dt = a.backend.timestep if a.backend is not None else sc.backend.timestep  # (validate builds no backend)
    control_dt = 1.0 / sc.rates.control_hz
    sub = control_dt / dt
    if abs(sub - round(sub)) > 1e-6 or round(sub) < 1:
        raise PluginSetupError(a.loaded.source, ("rates", "control_hz"), (),
                               f"rates.control_hz = {sc.rates.control_hz:g} gives a period of {control_dt:g} s, not "
                               f"a whole multiple of the backend timestep {dt:g} s")
    every = tuple(max(1, round(sc.rates.control_hz / s.rate_hz)) for s in a.sensors.values())
    return Schedule(control_dt, round(sub), int(round(sc.duration / control_dt)),
                    max(1, round(sc.rates.control_hz / sc.logging.rate_hz)),
                    max(1, round(sc.rates.control_hz / REACH_CHECK_HZ)), every)


def start_posture(a: Assembly) -> np.ndarray:
    """The task's start: a joint target's values, or a Cartesian one's first IK solution within the ranges."""
    task = a.sc.task
    name = task.start or task.order()[0]
    target = a.targets[name]
    if target.q is not None:
        return target.q.copy()
    try:
        solutions = a.robot.solve_ik(target.pose, free=target.free) if target.pose is not None else []
    except NotImplementedError:
        solutions = []
    lim = a.robot.model.limits
    inside = [s for s in solutions if np.all(s >= lim.lower) and np.all(s <= lim.upper)]
    if not inside:
        raise SetupError(f"task.start: target '{name}' is Cartesian and the robot's IK gives no configuration "
                         "for it within the joint ranges; start from a joint-space target")
    return inside[0]


def check_first_plan(a: Assembly) -> None:
    """Make the task's first plan without running it (``rehabkit validate``); a planner's refusal is located at
    the setting it names. Skipped where the run alone can plan: sensed targets, a controller planning itself."""
    sc = a.sc
    names = sc.task.order()
    sensed = any(t.sensor for t in sc.task.targets if t.name in names)
    if not names or sensed or a.controller.own_reference:
        return
    q0 = start_posture(a)
    try:
        plan = a.planner.plan(PlanRequest(0.0, q0, np.zeros_like(q0), [a.targets[n] for n in names], a.robot))
    except PlanningError as exc:
        raise first_plan_refusal(a, exc) from exc
    if a.planner.space == "joint":  # as the run's plan gate checks it
        from rehabkit.core.plan_gate import plan_breach

        if (breach := plan_breach(plan, a.robot.model)) is not None:
            raise first_plan_refusal(a, f"planned trajectory: {breach.describe()}")


def first_plan_refusal(a: Assembly, why: Exception | str) -> PluginSetupError:
    """The task's first plan failed or broke a limit: bad input, located at the target it names, else at the
    planner's setting it names, else at the planner."""
    exc = why if isinstance(why, Exception) else PlanningError(why)
    return _at_target(a, exc) or PluginSetupError.refused(a.loaded.source, ("planner",), "planner", a.sc.planner,
                                                          exc)


def _check_joint_targets(a: Assembly) -> None:
    """Joint values a target gives within the joint ranges in force (after a patient's admission)."""
    from rehabkit.core.limits import first_breach

    model = a.robot.model
    for name, target in a.targets.items():
        if target.q is None:
            continue
        breach = first_breach(model.limits, model.joint_names, target.q[None], None, np.zeros(1),
                              revolute=model.revolute)
        if breach is not None:
            why = PlanningError(f"target '{name}': its joint values put {breach.describe()}")
            raise _at_target(a, why, "task") or SetupError(str(why))


def _at_target(a: Assembly, exc: Exception, kind: str = "planner") -> PluginSetupError | None:
    """A refusal naming one target (out of reach, say), located at where that target is given."""
    named = re.match(r"target '([^']+)'", str(exc))
    index = next((i for i, t in enumerate(a.sc.task.targets) if named and t.name == named[1]), None)
    if index is None:
        return None
    spec = a.sc.task.targets[index]
    key = next(k for k in ("position", "joints_deg", "joints_rad", "same_as", "random", "sensor")
               if getattr(spec, k) is not None)
    prefix = f"planner '{a.sc.planner.type}': " if kind == "planner" else ""
    return PluginSetupError(a.loaded.source, ("task", "targets", index, key), (), f"{prefix}{exc}")
