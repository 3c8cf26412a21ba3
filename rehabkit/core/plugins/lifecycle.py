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
1. :func:`rehabkit_configure_robot` — before the robot is built (adapt its settings);
2. :func:`rehabkit_narrow_limits` — the robot built: tighter joint limits;
3. :func:`rehabkit_force_limit` — an interaction-force limit;
4. :func:`rehabkit_admit_targets` — the task's targets resolved: refuse or replace some;
5. :func:`rehabkit_run_opened` — the run's session open: a :class:`RunTap` taking each sensor reading as it comes;
6. :func:`rehabkit_run_finished` — the run over: metrics, summary sections, logged series.

:func:`rehabkit_metrics` describes the metrics an extension adds. The loop itself
calls no hooks: what happens every step belongs to the plugins and the safety layer (a tap is called by the
timeline with each reading, as the log is).
An extension's module is imported for every run: import heavy things inside the hooks.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import pluggy

from rehabkit.core.kinds.metric import Metric

# The hooks' arguments: ``setup`` is the run's :class:`rehabkit.core.setup.assembly.Assembly`, ``record`` its
# :class:`rehabkit.core.results.record.RunRecord`, narrowings :class:`rehabkit.core.setup.limits.Narrowing`
# (not imported here: those modules call the hooks).
Assembly = RunRecord = Narrowing = Any
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

    def discard(self) -> None:
        """The run failed: drop whatever was begun (default: nothing)."""


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
def rehabkit_configure_robot(setup: Assembly) -> None:
    """Before the robot is built: may replace ``setup.robot_config`` (a copy with other settings) and
    record why in ``setup.sections``."""

@hookspec
def rehabkit_narrow_limits(setup: Assembly) -> list[Narrowing]:
    """The robot built (``setup.robot``): tighter joint limits. Raise ``ScenarioError`` for what the
    scenario got wrong (located), ``ValueError`` for what can't be put together."""

@hookspec
def rehabkit_force_limit(setup: Assembly) -> float | None:
    """An interaction-force limit [N] at the hand; the tightest of the envelope's and all extensions' holds."""

@hookspec
def rehabkit_admit_targets(setup: Assembly) -> None:
    """The task's fixed targets resolved (``setup.targets``, within ``setup.limits``): refuse one
    (``ScenarioError``, located) or replace it in place and list it in ``setup.replaced``."""

@hookspec
def rehabkit_run_opened(setup: Assembly) -> RunTap | None:
    """The run's session open, standing at the start: a tap for the readings as they come, or None."""

@hookspec
def rehabkit_run_finished(setup: Assembly, record: RunRecord) -> Contribution | None:
    """The run over: its metrics, summary sections and series from the run record."""


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
            for ep in metadata.entry_points(group=GROUP):
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

    def plugin_slots(self, registry: Any) -> dict[tuple[str, str], str]:
        """(section, key) → plugin kind, for every extension section holding a plugin's settings."""
        return {(name, key): kind for name, (_, section) in self.sections(registry).items()
                for key, kind in section.plugins.items()}


_DEFAULT: Extensions | None = None


def default_extensions() -> Extensions:
    """The process-wide installed extensions, loaded on first use."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = Extensions()
    return _DEFAULT
