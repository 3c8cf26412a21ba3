"""Putting a run together: robot, limits, plugins, safety layer, targets.

One function, :func:`assemble`, for ``rehabkit run`` and ``rehabkit validate``: the
latter builds everything but the backend (``upto="plugins"``, a dry-run context) and
then makes the first plan (:func:`rehabkit.core.setup.first_plan.check_first_plan`), and so refuses what a run's
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

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from rehabkit.core.kinds.capabilities import CompliantGaps
from rehabkit.core.kinds.context import Seeds
from rehabkit.core.kinds.errors import apart
from rehabkit.core.kinds.interfaces import (
    Backend,
    Context,
    Controller,
    EmbodiedPatient,
    Patient,
    Planner,
    PlanningError,
    Robot,
    Sensor,
    Target,
)
from rehabkit.core.kinds.names import nearest
from rehabkit.core.plugins.lifecycle import Extensions
from rehabkit.core.plugins.registry import PluginRegistry
from rehabkit.core.safety.layer import SafetySetup
from rehabkit.core.scenario.errors import Diagnostic, ScenarioError
from rehabkit.core.scenario.loader import LoadedScenario
from rehabkit.core.setup.checks import (
    at_target,
    check_capabilities,
    check_duration,
    check_expectations,
    check_joint_targets,
    check_loads,
    check_robot_model,
    check_scene_names,
    check_sensor_settings,
    metric_catalogue,
)
from rehabkit.core.setup.errors import PluginSetupError, SetupError
from rehabkit.core.setup.force_source import ForceSource
from rehabkit.core.setup.limits import (
    LimitSources,
    envelope_narrowings,
    narrow,
    unknown_joint,
    wrong_kind_settings,
    wrong_unit_keys,
)
from rehabkit.core.setup.person_safety import patient_slot, person_and_safety
from rehabkit.core.setup.space import JointSpace, reference_space
from rehabkit.core.setup.targets import resolve_targets
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
    backend_warnings: list[str] = field(default_factory=list)  # (validate: what the backend's check says, not refuses)
    catalogue: Any = None  # every metric the run can report, described (a MetricCatalogue), made once at assembly
    sections: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)  # each extension's ExtensionState as set up (its notes)
    sensors: dict[str, Sensor] = field(default_factory=dict)
    backend: Backend | None = None
    planner: Planner | None = None
    event_planners: dict[int, Planner] = field(default_factory=dict)  # replan events with planner settings
    controller: Controller | None = None
    patient: Patient | None = None
    space: JointSpace | None = None  # the reference's space (joint or Cartesian: a CartesianSpace)
    force_source: ForceSource | None = None  # the interaction force each control step, and its last value
    safety: SafetySetup | None = None  # the rules and limits; each run session makes its own layer from them
    schedule: Schedule | None = None
    patient_slot: Any = None  # where the scenario holds the simulated patient's settings (a PatientSlot), if it does

    @property
    def sc(self):
        """The validated scenario."""
        return self.loaded.model

    def backend_class(self) -> type[Backend] | None:
        """The scenario's backend plugin's class (None for a factory that is not a Backend class)."""
        factory = self.registry.get("backend", self.sc.backend.type).factory
        return factory if isinstance(factory, type) and issubclass(factory, Backend) else None

    def make(self, kind: str, config, path: tuple[str, ...], check_only: bool = False) -> Any:
        """Build plugin ``config.type`` of ``kind`` from the section at ``path`` (``check_only``: a backend's
        :meth:`~rehabkit.core.kinds.backend.Backend.check` instead, for ``validate``); whatever it raises becomes
        a :class:`PluginSetupError` located in the scenario file (a ``SettingError`` at its setting)."""
        info = self.registry.get(kind, config.type)
        try:
            if check_only:
                backend = self.backend_class()
                return backend.check(config, self.context) if backend is not None else None
            return info.factory(config, self.context)
        except (ValueError, PlanningError) as exc:
            raise PluginSetupError.refused(self.loaded.source, path, kind, config, exc) from exc
        except (ScenarioError, SetupError):
            raise
        except Exception as exc:  # a bug in the plugin: said at its type, naming the package to report it to
            raise PluginSetupError(self.loaded.source, (*path, "type"), (
                f"{kind} '{config.type}' failed while it was built: {type(exc).__name__}: {exc} (a bug in the "
                f"plugin, package {info.provider.package} {info.provider.version}; `rehabkit --debug …` shows "
                "its traceback)"), provider=info.provider) from exc


def assemble(loaded: LoadedScenario, registry: PluginRegistry, extensions: Extensions, out_dir: Path | None = None,
             upto: Literal["targets", "plugins", "run"] = "run", plan: Callable | None = None,
             note: Callable[[float, str], None] | None = None, latest: Callable | None = None,
             force: Callable | None = None) -> Assembly:
    """Build the run of ``loaded`` (see the module docstring); ``plan``, ``note``, ``latest`` and ``force`` go to the
    plugins' context (``Context.plan``, ``note``, ``reading`` and ``interaction_force``: what the run session says).

    Raises:
        ScenarioError: something the scenario got wrong, located in its file.
        SetupError: the plugins can't be put together as configured.
    """
    sc = loaded.model
    slot = patient_slot(sc, registry, extensions)
    seeds = Seeds(sc.seed)
    ctx = Context(loaded.directory, seeds.generator(), 1.0 / sc.rates.control_hz, world=sc.world, seeds=seeds,
                  out_dir=out_dir, seed=sc.seed, safety=sc.safety, patient=slot.section if slot else None, plan=plan,
                  note=note, dry_run=upto != "run", plugins=registry, latest=latest)
    a = Assembly(loaded, registry, extensions, out_dir, sc.robot, ctx, patient_slot=slot)
    extensions.configure_robot(a)
    a.context = replace(ctx, robot_spec=a.robot_config.model_dump(mode="json"))
    a.robot = a.make("robot", a.robot_config, ("robot",))
    check_robot_model(a)
    a.context = replace(a.context, robot=a.robot)
    _narrow_limits(a)
    check_capabilities(a)
    check_scene_names(a)
    try:
        a.targets = resolve_targets(sc.task, a.robot, sc.seed)
    except PlanningError as exc:
        said, fix = apart(exc)
        raise at_target(a, exc, "task") or SetupError(f"task: {said}", fix=fix) from exc
    extensions.admit_targets(a)
    check_joint_targets(a)
    check_duration(a)
    if upto == "targets":
        return a
    # sensors before the backend: their instruments go into the scene it builds; the sensors, the planner and the
    # controller are each built even when another refused, so that every refusal is said at once
    refused: list[PluginSetupError] = []

    def attempt(kind: str, config, path: tuple) -> Any:
        try:
            return a.make(kind, config, path)
        except PluginSetupError as exc:
            refused.append(exc)
            return None

    built = {name: attempt("sensor", cfg, ("sensors", name)) for name, cfg in sc.sensors.items()}
    a.sensors = {name: s for name, s in built.items() if s is not None}
    a.context = replace(a.context, instruments=[i for s in a.sensors.values() for i in s.instruments()])
    if not refused:
        check_loads(a)
    check_sensor_settings(a)
    a.planner = attempt("planner", sc.planner, ("planner",))
    for i, ev in enumerate(sc.task.events):
        if ev.planner is not None and a.planner is not None:  # (validated with the scenario, each located)
            config = type(sc.planner).model_validate({**sc.planner.model_dump(), **ev.planner})
            a.event_planners[i] = a.make("planner", config, ("task", "events", i, "planner"))
    space = a.planner.space if a.planner is not None else a.context.reference_space
    a.context = replace(a.context, reference_space=space, interaction_force=force or _no_force)
    a.controller = attempt("controller", sc.controller, ("controller",))
    if refused:
        raise PluginSetupError.together(refused)
    takes = "joint" if a.controller.reference == "own" else a.controller.reference  # (own: asks for joint plans)
    if a.planner.space != takes:
        raise PluginSetupError(a.loaded.source, ("controller", "type"),
                               f"planner '{sc.planner.type}' plans in {a.planner.space} space but controller "
                               f"'{sc.controller.type}' takes {takes} references", fix="pick a matching pair")
    a.space = reference_space(a)
    for t in sc.task.targets:
        if t.sensor and t.sensor not in a.sensors:
            raise SetupError(f"target '{t.name}' follows sensor '{t.sensor}', which is not in 'sensors'",
                             fix=nearest(t.sensor, a.sensors))
    person_and_safety(a)
    if upto == "run":  # last: a backend may start processes (a hardware link's bridge); its scene holds the
        # sensors' instruments and an embodied patient's body
        bodies = (a.patient,) if isinstance(a.patient, EmbodiedPatient) else ()
        a.context = replace(a.context, bodies=bodies)
        a.backend = a.make("backend", sc.backend, ("backend",))
        a.safety = replace(a.safety, delay=a.backend.loop_delay,
                           # (its gaps in the commands bridged yielding, in a yield)
                           on_yield=a.backend.comply if isinstance(a.backend, CompliantGaps) else None)
    else:
        a.backend_warnings = list(a.make("backend", sc.backend, ("backend",), check_only=True) or [])
    a.catalogue = metric_catalogue(a)
    check_expectations(a)
    a.schedule = _schedule(a)
    return a


def _no_force() -> None:
    """``Context.interaction_force()`` outside a run: no force was checked."""
    return None


def _narrow_limits(a: Assembly) -> None:
    """Robot ∩ extensions ∩ envelope, set on the robot model; joint names the robot lacks refused where written."""
    sc, model, source = a.sc, a.robot.model, a.loaded.source
    problems = [Diagnostic(source.key_marks.get(("safety", "joints", n), source.value_marks[()]),
                           f"safety.joints.{n}", *said) for n in sc.safety.joints if (said := unknown_joint(n, model))]
    # a revolute joint's limits in degrees, a prismatic joint's in metres: the other kind's key refused where written
    problems += [Diagnostic(source.key_marks.get(("safety", "joints", w.joint, w.key),
                                                 source.key_marks.get(("safety", "joints", w.joint),
                                                                      source.value_marks[()])),
                            f"safety.joints.{w.joint}.{w.key}", w.problem, w.fix)
                 for w in wrong_unit_keys({n: env.given() for n, env in sc.safety.joints.items()}, model)]
    # a setting for every joint of a kind the robot lacks (wall_m on a robot whose joints all turn), where written
    written = {("safety",): _written(sc.safety),
               **{("safety", "reactions", rule): _written(r) for rule, r in sc.safety.reactions.items()}}
    for path, keys in written.items():
        problems += [Diagnostic(_nearest_mark(source, (*path, key)), ".".join((*path, key)), *said)
                     for key, said in wrong_kind_settings(keys, model).items()]
    try:
        asked = a.extensions.narrow_limits(a)
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


def _nearest_mark(source, path: tuple):
    """Where ``path`` was written, else its nearest written ancestor (a ``--set`` of the mapping holding it)."""
    for n in range(len(path), 0, -1):
        if path[:n] in source.key_marks:
            return source.key_marks[path[:n]]
    return source.value_marks[()]


def _written(section) -> list[str]:
    """The keys a section's file set, in the order its model declares them."""
    return [k for k in type(section).model_fields if k in section.model_fields_set]


def _schedule(a: Assembly) -> Schedule:
    sc = a.sc
    control_dt = 1.0 / sc.rates.control_hz
    if a.backend is not None:
        dt = a.backend.timestep
    else:  # (validate builds no backend: its class says what its step will be)
        backend = a.backend_class()
        dt = backend.timestep_for(sc.backend, control_dt) if backend is not None else sc.backend.timestep
    sub = control_dt / dt
    if abs(sub - round(sub)) > 1e-6 or round(sub) < 1:
        raise PluginSetupError(a.loaded.source, ("rates", "control_hz"),
                               f"rates.control_hz = {sc.rates.control_hz:g} gives a period of {control_dt:g} s, not "
                               f"a whole multiple of the backend timestep {dt:g} s")
    every = tuple(max(1, round(sc.rates.control_hz / sc.sensors[name].rate_hz)) for name in a.sensors)
    return Schedule(control_dt, round(sub), int(round(sc.duration / control_dt)),
                    max(1, round(sc.rates.control_hz / sc.logging.rate_hz)),
                    max(1, round(sc.rates.control_hz / REACH_CHECK_HZ)), every)
