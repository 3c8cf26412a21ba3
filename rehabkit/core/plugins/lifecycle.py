"""Run-lifecycle hooks: how a layer above the core (the rehab layer, a lab's own) takes part in a run.

An *extension* is a module registered under the entry-point group
``rehabkit.extensions`` (the entry point's name is the extension's), one line of
``pyproject.toml``::

    [project.entry-points."rehabkit.extensions"]
    my-layer = "my_package.layer"

It implements any of the hooks below with ``@rehabkit.hookimpl``. Every installed
extension takes part in every run (and in ``rehabkit validate``, as far as the
setup goes there), in this order:

0. :func:`rehabkit_scenario_sections` — the scenario sections the layer owns (validated, located, suggested and
   in ``rehabkit schema`` as the core's own are: the scenario model is built with them);
1. :func:`rehabkit_configure_robot` — before the robot is built: other robot settings (:class:`RobotSettings`);
2. :func:`rehabkit_narrow_limits` — the robot built: tighter joint limits;
3. :func:`rehabkit_force_limit` — an interaction-force limit;
4. :func:`rehabkit_admit_targets` — the task's targets resolved: refuse some, or replace them (:class:`Admission`);
5. :func:`rehabkit_run_opened` — the run's session open: a :class:`RunTap` taking each sensor reading as it comes;
6. :func:`rehabkit_run_finished` — the run over: metrics, summary sections, logged series (:class:`Contribution`).

Each hook is given what it reads — the validated scenario, the robot, a read-only :class:`RunInfo` — and
*returns* what it contributes; the core applies it. An extension writes nothing of the run's: what it keeps
between its hooks is its :class:`ExtensionState` (the notes its :class:`RobotSettings` gave, the tap it opened),
kept by the core per run and per extension and given back to it at the run's opening and end.

:func:`rehabkit_metrics` describes the metrics an extension adds. The loop itself
calls no hooks: what happens every step belongs to the plugins and the safety layer (a tap is called by the
timeline with each reading, as the log is).
An extension's module is imported for every run: import heavy things inside the hooks.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pluggy

from rehabkit.core.kinds.interfaces import Backend, Patient, Robot, Sensor, Target
from rehabkit.core.kinds.metric import Metric
from rehabkit.core.plugins.discovery import installed_entry_points
from rehabkit.models.robot_model import JointLimits, RobotModel

# Types of the stages above this one (not imported here: those modules call the hooks): ``Scenario`` the validated
# scenario (:class:`rehabkit.core.scenario.models.ScenarioBase`, with the extensions' sections), ``Source`` where
# its settings were written (:class:`rehabkit.core.scenario.source.Source`: marks to locate a refusal with),
# ``RunRecord`` :class:`rehabkit.core.results.record.RunRecord`, ``Narrowing`` and ``LimitSources``
# :mod:`rehabkit.core.setup.limits`, ``Schedule`` :class:`rehabkit.core.setup.assembly.Schedule`, ``Assembly``
# :class:`rehabkit.core.setup.assembly.Assembly` (the core's alone: no hook is given it).
Scenario = Source = RunRecord = Narrowing = LimitSources = Schedule = Assembly = Any
PROJECT = "rehabkit"
GROUP = "rehabkit.extensions"
hookspec = pluggy.HookspecMarker(PROJECT)


@dataclass
class Contribution:
    """What an extension adds when a run is over.

    Attributes:
        metrics: Scalars merged into the run's metrics (``expect:`` can bound them).
        sections: Top-level ``summary.json`` sections (name → JSON-ready value).
        series: Time series for the Rerun log: entity path → (times [s], values).
    """

    metrics: dict[str, float] = field(default_factory=dict)
    sections: dict[str, Any] = field(default_factory=dict)
    series: dict[str, tuple[Any, Any]] = field(default_factory=dict)


class RunTap:
    """What an extension takes from a run as it goes (returned by :func:`rehabkit_run_opened`): each sensor reading
    when it is taken (``t`` the time it was taken at, ``name`` the sensor's, ``reading`` its values as the sensor
    gave them). The run's end reaches the extension through :func:`rehabkit_run_finished`; a run that fails calls
    :meth:`discard`, so that nothing half-written is left."""

    def reading(self, t: float, name: str, reading: dict[str, Any]) -> None:
        """A sensor's reading (default: ignored)."""

    def logged(self, t: float, k: int) -> None:
        """The run at a logged step (the log rate: control step ``k``, at ``t``), e.g. to ask the backend for what
        the trace does not hold (default: nothing)."""

    def follow(self, trace: Any, movements: Callable[[], Sequence[Any]]) -> None:
        """The run as the loop goes (read-only), given once as the session opens: ``trace`` the trace the loop fills
        (:class:`~rehabkit.core.kinds.trace.Trace`), ``movements()`` the movements planned so far
        (:class:`~rehabkit.core.results.record.Movement`: ``k0`` the step each begins). When :meth:`logged` is called
        for step ``k``, the trace's rows up to ``k`` and the movements begun by then are final: e.g. to write them as
        the run goes (default: nothing)."""

    def discard(self) -> None:
        """The run failed: drop whatever was begun (default: nothing)."""


@dataclass(frozen=True)
class RobotSettings:
    """What :func:`rehabkit_configure_robot` contributes: the robot section to build the robot from instead of the
    one it was given (``config``: a copy with other settings, e.g. ``robot_config.model_copy(update=…)``), and
    ``notes`` for the extension's own later hooks (why: given back as :attr:`ExtensionState.notes`)."""

    config: Any
    notes: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Admission:
    """What :func:`rehabkit_admit_targets` contributes: ``targets`` the ones it replaces (name → the target taking
    its place, an alias of a replaced target included), ``replaced`` a JSON-ready line for each replacement (what
    ``rehabkit validate`` says, and :attr:`RunInfo.replaced`). A target it refuses is refused by raising
    ``ScenarioError`` (located), as :func:`rehabkit_narrow_limits` refuses."""

    targets: Mapping[str, Target] = field(default_factory=dict)
    replaced: tuple[dict[str, Any], ...] = ()


@dataclass(frozen=True)
class RunInfo:
    """The run as :func:`rehabkit_run_opened` and :func:`rehabkit_run_finished` read it (read-only; built by the
    core for each call).

    Attributes:
        scenario: The validated scenario (the extensions' sections as attributes: ``scenario.patient``).
        robot: The robot; ``robot.model`` its kinematics, with the run's (narrowed) limits set on it.
        limits: The run's joint limits (the robot's, narrowed by the envelope and the extensions);
            ``limit_sources`` who narrowed what (:class:`rehabkit.core.setup.limits.LimitSources`).
        targets: The task's targets as admitted (replacements in place), by name.
        replaced: Every extension's :attr:`Admission.replaced` lines.
        sensors: The run's sensors, by name; ``backend`` the backend; ``patient`` the simulated person (None:
            none, or a real one).
        schedule: The loop's timing (:class:`rehabkit.core.setup.assembly.Schedule`: ``control_dt`` [s],
            ``log_every``, …).
        out_dir: Where the run writes its files (None: nowhere).
        resolve: A path as the scenario wrote it → the file (relative to the scenario's folder).
    """

    scenario: Scenario
    robot: Robot
    limits: JointLimits
    limit_sources: LimitSources
    targets: Mapping[str, Target]
    replaced: tuple[dict[str, Any], ...]
    sensors: Mapping[str, Sensor]
    backend: Backend | None
    patient: Patient | None
    schedule: Schedule
    out_dir: Path | None
    resolve: Callable[[str | Path], Path]


@dataclass(frozen=True)
class ExtensionState:
    """What one extension keeps between its hooks in one run, kept by the core and given back to it:
    ``notes`` its :attr:`RobotSettings.notes` (empty: it gave none), ``tap`` the :class:`RunTap` its
    :func:`rehabkit_run_opened` returned for the run's session (None: none, or before the session opens)."""

    notes: Mapping[str, Any] = field(default_factory=dict)
    tap: RunTap | None = None


@dataclass(frozen=True)
class Section:
    """A top-level scenario section an extension owns: its pydantic model (a ``StrictModel``), its value when a
    scenario leaves it out (``None``: absent), and a line for the schema. ``file``: the section may be given as the
    path of a YAML file holding it (relative to the file naming it; errors point into that file). ``plugins``: keys
    of the section holding a plugin's settings → the plugin kind (``{"model": "patient"}``): their ``type`` is
    checked, suggested and swapped with ``--set`` as the core's plugin sections are, and the run builds the plugin."""

    model: type
    default: Any = None
    description: str = ""
    file: bool = False
    plugins: dict[str, str] = field(default_factory=dict)


@hookspec
def rehabkit_scenario_sections(registry: Any) -> dict[str, Section]:
    """The top-level sections this layer owns: name → :class:`Section`. ``registry`` is the run's plugin registry
    (:class:`~rehabkit.core.plugins.registry.PluginRegistry`), for a section holding plugin settings."""

@hookspec
def rehabkit_metrics() -> list[Metric]:
    """Descriptions of the metrics this extension reports."""

@hookspec
def rehabkit_configure_robot(scenario: Scenario, source: Source, robot_config: Any) -> RobotSettings | None:
    """Before the robot is built: other settings for it (:class:`RobotSettings`), or None. ``robot_config`` is
    the robot section as the extensions before this one left it (the scenario's, at first); ``source`` says where
    each setting was written (``("robot", name) in source.value_marks``: the scenario set it)."""

@hookspec
def rehabkit_narrow_limits(scenario: Scenario, source: Source, model: RobotModel) -> list[Narrowing]:
    """The robot built (``model``: its kinematics and its own limits): tighter joint limits. Raise
    ``ScenarioError`` for what the scenario got wrong (located with ``source``), ``ValueError`` for what can't be
    put together."""

@hookspec
def rehabkit_force_limit(scenario: Scenario) -> float | None:
    """An interaction-force limit [N] at the hand; the tightest of the envelope's and all extensions' holds."""

@hookspec
def rehabkit_admit_targets(scenario: Scenario, source: Source, targets: Mapping[str, Target], robot: Robot,
                           robot_limits: JointLimits, limit_sources: LimitSources) -> Admission | None:
    """The task's fixed targets resolved (``targets``, read-only; ``robot.model.limits`` the run's narrowed
    limits, ``robot_limits`` the robot's own, ``limit_sources`` who narrowed what): the ones replaced
    (:class:`Admission`), or None. Refuse one by raising ``ScenarioError`` (located with ``source``)."""

@hookspec
def rehabkit_run_opened(run: RunInfo, state: ExtensionState) -> RunTap | None:
    """The run's session open, standing at the start: a tap for the readings as they come, or None (it is given
    back as ``state.tap`` at the run's end)."""

@hookspec
def rehabkit_run_finished(run: RunInfo, record: RunRecord, state: ExtensionState) -> Contribution | None:
    """The run over: its metrics, summary sections and series (:class:`Contribution`) from the run record, or
    None. ``state``: what this extension kept (its notes, its tap)."""


@dataclass(frozen=True)
class BrokenExtension:
    name: str
    error: str


class Extensions:
    """The installed extensions, loaded once; ``hook`` calls them all."""

    def __init__(self, modules: Iterable[tuple[str, object]] = (), entry_points: bool = True):
        self.pm = pluggy.PluginManager(PROJECT)
        self.pm.add_hookspecs(sys.modules[__name__])
        self._sections: tuple[Any, dict] | None = None  # (the registry's state, its sections): see sections()
        self.broken: list[BrokenExtension] = []
        found: list[tuple[str, Any]] = []
        if entry_points:
            seen = set()
            for ep in installed_entry_points().select(group=GROUP):  # (the scan discovery made for the plugins)
                if (ep.name, ep.value) not in seen:
                    seen.add((ep.name, ep.value))
                    found.append((ep.name, ep.load))
        found += [(name, (lambda m=m: m)) for name, m in modules]
        for name, load in found:
            try:
                self.pm.register(load(), name=name)
                self.pm.check_pending()
            except Exception as exc:  # noqa: BLE001 (kept and reported: runs refuse to start without it)
                self.broken.append(BrokenExtension(name, f"{type(exc).__name__}: {exc}"))
                if self.pm.get_plugin(name) is not None:
                    self.pm.unregister(name=name)

    @property
    def hook(self):
        return self.pm.hook

    def names(self) -> list[str]:
        return sorted(n for n, _ in self.pm.list_name_plugin())

    def metrics(self) -> list[Metric]:
        return [m for ms in self.hook.rehabkit_metrics() for m in ms]

    def sections(self, registry: Any) -> dict[str, tuple[str, Section]]:
        """Every extension's scenario sections: name → (extension, section); two claiming one name is an error.

        Asked for by each stage of a scenario's load and setup; made again only when ``registry`` has loaded more
        plugins since (a section's model may take the settings of a plugin kind: the patient profile's ``model``).
        """
        state = (id(registry), tuple(len(loaded) for loaded in registry.plugins.values()))
        if self._sections is not None and self._sections[0] == state:
            return self._sections[1]
        out: dict[str, tuple[str, Section]] = {}
        for impl in self.hook.rehabkit_scenario_sections.get_hookimpls():
            for name, section in impl.function(registry=registry).items():
                if name in out:
                    raise ValueError(f"scenario section '{name}' is claimed by extensions '{out[name][0]}' and "
                                     f"'{impl.plugin_name}'; uninstall one")
                out[name] = (impl.plugin_name, section)
        self._sections = state, dict(sorted(out.items()))
        return self._sections[1]

    # -- the run-lifecycle hooks, called by the core: each given what it reads, its answers applied here --------
    # ``a`` is the run's Assembly: only the core (these methods) writes it, while it is assembled. ``a.extras`` holds
    # each extension's ExtensionState by its name as the set-up left it (its notes); a run's taps are its session's.

    def _each(self, hook: str) -> Iterator[tuple[str, Callable[..., Any]]]:
        """Each extension implementing ``hook``, in pluggy's order: its name and a call taking the hook's arguments
        by name (given those its implementation names, as pluggy gives them)."""
        for impl in reversed(getattr(self.hook, hook).get_hookimpls()):
            yield impl.plugin_name, lambda f=impl.function, names=impl.argnames, **kw: f(*(kw[n] for n in names))

    def configure_robot(self, a: Assembly) -> None:
        """:func:`rehabkit_configure_robot`: ``a.robot_config`` as the extensions set it, in turn (each given the
        last one's), and each extension's notes in its :class:`ExtensionState`."""
        for name, call in self._each("rehabkit_configure_robot"):
            settings = call(scenario=a.sc, source=a.loaded.source, robot_config=a.robot_config)
            if settings is not None:
                a.robot_config = settings.config
                a.extras[name] = replace(self.state(a, name), notes=dict(settings.notes))

    def narrow_limits(self, a: Assembly) -> list[Narrowing]:
        """:func:`rehabkit_narrow_limits`: every extension's narrowings, in pluggy's order (the core narrows)."""
        found = self.hook.rehabkit_narrow_limits(scenario=a.sc, source=a.loaded.source, model=a.robot.model)
        return [narrowing for narrowings in found for narrowing in narrowings or ()]

    def admit_targets(self, a: Assembly) -> None:
        """:func:`rehabkit_admit_targets`: the replacements put into ``a.targets`` (an extension's after those
        before it) and listed in ``a.replaced``; a refusal is raised by the extension."""
        admitted = [x for x in self.hook.rehabkit_admit_targets(
            scenario=a.sc, source=a.loaded.source, targets=MappingProxyType(dict(a.targets)), robot=a.robot,
            robot_limits=a.robot_limits, limit_sources=a.limit_sources) if x is not None]
        for admission in admitted:
            a.targets.update(admission.targets)
        a.replaced = [line for admission in admitted for line in admission.replaced]

    def run_opened(self, a: Assembly) -> tuple[list[RunTap], dict[str, ExtensionState]]:
        """:func:`rehabkit_run_opened`: the run's taps, and each extension's :class:`ExtensionState` for this run
        (its tap in it): the run session's to keep — the Assembly is the same for every session made from it."""
        run, taps, states = run_info(a), [], {}
        for name, call in self._each("rehabkit_run_opened"):
            tap = call(run=run, state=self.state(a, name))
            if tap is not None:
                states[name] = replace(self.state(a, name), tap=tap)
                taps.append(tap)
        return taps, states

    def run_finished(self, a: Assembly, record: RunRecord,
                     states: Mapping[str, ExtensionState] | None = None) -> list[Contribution]:
        """:func:`rehabkit_run_finished`: the extensions' contributions, in pluggy's order; ``states``: the run's
        (:meth:`run_opened`'s), else what the extensions noted while the run was assembled."""
        run, out, states = run_info(a), [], states or {}
        for name, call in self._each("rehabkit_run_finished"):
            state = states.get(name) or self.state(a, name)
            if (contribution := call(run=run, record=record, state=state)) is not None:
                out.append(contribution)
        return out

    @staticmethod
    def state(a: Assembly, name: str) -> ExtensionState:
        """What extension ``name`` keeps in the run ``a`` (:class:`ExtensionState`)."""
        return a.extras.get(name) or ExtensionState()

    def plugin_slots(self, registry: Any) -> dict[tuple[str, str], str]:
        """(section, key) → plugin kind, for every extension section holding a plugin's settings."""
        return {(name, key): kind for name, (_, section) in self.sections(registry).items()
                for key, kind in section.plugins.items()}


def run_info(a: Assembly) -> RunInfo:
    """The run ``a`` (an Assembly) as the run hooks read it."""
    return RunInfo(scenario=a.sc, robot=a.robot, limits=a.limits, limit_sources=a.limit_sources,
                   targets=MappingProxyType(dict(a.targets)), replaced=tuple(a.replaced),
                   sensors=MappingProxyType(dict(a.sensors)), backend=a.backend, patient=a.patient,
                   schedule=a.schedule, out_dir=a.out_dir, resolve=a.context.resolve)


_DEFAULT: Extensions | None = None


def default_extensions() -> Extensions:
    """The process-wide installed extensions, loaded on first use."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = Extensions()
    return _DEFAULT
