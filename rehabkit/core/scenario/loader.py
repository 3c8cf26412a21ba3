"""YAML → validated scenario, with every error located at ``file:line:col``.

The YAML is composed once into nodes; each key path gets the mark of its key
and of its value. ``extends:`` files are merged underneath (deep merge; a
section whose plugin ``type`` changes is replaced, not merged), then
``--set a.b=value`` overrides on top. Plugin ``type`` names are checked against
the registry first (with suggestions), then the whole document is validated by
the pydantic model built from the installed plugins and the layers' sections, and each pydantic error is
mapped back to the longest key path the YAML actually has (:mod:`rehabkit.core.scenario.validation`).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rehabkit.core.plugins.lifecycle import Extensions, default_extensions
from rehabkit.core.plugins.registry import PluginRegistry, default_registry
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.scenario.file_settings import anchor_file_settings
from rehabkit.core.scenario.models import PLUGIN_SECTIONS, ScenarioBase
from rehabkit.core.scenario.source import (  # noqa: F401 (deep_merge: part of this module's API)
    KeyPath,
    Source,
    _dotted,
    apply_overrides,
    deep_merge,
    parse_override,
    read_with_extends,
    with_file_sections,
)
from rehabkit.core.scenario.validation import validate_source


@dataclass
class LoadedScenario:
    """A validated scenario and its provenance."""

    model: ScenarioBase
    path: Path
    source: Source

    @property
    def directory(self) -> Path:
        return self.path.parent


def plugin_kind(path: list[str], slots: Mapping[tuple[str, str], str]) -> str | None:
    """The plugin kind of a section path (``controller``, ``sensors.camera``, a layer's slot such as
    ``patient.model``), if it is one."""
    if len(path) == 1 and path[0] in PLUGIN_SECTIONS:
        return PLUGIN_SECTIONS[path[0]]
    if len(path) == 2:
        return "sensor" if path[0] == "sensors" else slots.get((path[0], path[1]))
    return None


def _fit_new_types(src: Source, overrides: Iterable[str] | Mapping[str, Any], registry: PluginRegistry,
                   slots: Mapping[tuple[str, str], str]) -> None:
    """``--set controller.type=other``: settings the other plugin has no field for are dropped, with a warning.

    Shared settings stay (a planner's speed limits when switching planners); the new plugin's
    defaults fill the rest.
    """
    items = overrides.items() if isinstance(overrides, Mapping) else (parse_override(o) for o in overrides)
    for key, value in items:
        parts = key.split(".") if isinstance(key, str) else list(key)
        kind = plugin_kind(parts[:-1], slots) if parts[-1:] == ["type"] else None
        info = registry.find(kind, value) if kind and isinstance(value, str) else None
        node: Any = src.data
        for part in parts[:-1]:
            node = node.get(part) if isinstance(node, dict) else None
        if info is None or not isinstance(node, dict):
            continue  # an unknown type is reported by validation, with suggestions
        dropped = [k for k in node if k != "type" and k not in info.config.model_fields]
        for k in dropped:
            del node[k]
        if dropped:
            warnings.warn(f"--set {'.'.join(parts)}={value}: dropped {', '.join(dropped)} ('{value}' has no such "
                          f"settings; its defaults apply)", stacklevel=2)


def load_scenario(
    path: str | Path,
    overrides: Iterable[str] | Mapping[str, Any] = (),
    registry: PluginRegistry | None = None,
    origin: Path | None = None,
    extensions: Extensions | None = None,
    grid: Mapping[str, Any] | None = None,
) -> LoadedScenario:
    """Read, merge, override and validate a scenario file.

    Args:
        path: The scenario YAML.
        overrides: ``["a.b=1", ...]`` as on the command line, or ``{"a.b": 1}``.
        registry: Plugins to validate against (default: the installed ones).
        origin: For a run's snapshot of a scenario: the file it was taken from (relative paths resolve
            from its folder, and the run reports it as its scenario).
        extensions: The layers whose sections the scenario may have (default: the installed ones).
        grid: A sweep's grid point, ``{"a.b": 1}``, applied after ``overrides`` (its errors said at ``<--grid KEY>``).

    Raises:
        ScenarioError: with one :class:`Diagnostic` per problem.
    """
    path = Path(path)
    if not path.exists():
        raise ScenarioError([Diagnostic(Mark(str(path), 0, 0), "", "no such file")])
    registry = registry or default_registry()
    extensions = extensions or default_extensions()
    sections = extensions.sections(registry)
    as_files = [name for name, (_, section) in sections.items() if section.file]
    src = read_with_extends(path)
    with_file_sections(src, path, as_files)
    try:
        apply_overrides(src, overrides)
    except ValueError as exc:
        raise ScenarioError([Diagnostic(Mark("<--set>", 0, 0), "", str(exc))]) from None
    apply_overrides(src, grid or {}, flag="--grid")
    with_file_sections(src, path, as_files)  # --set patient=FILE (a sweep over profiles), from the scenario's folder
    _fit_new_types(src, overrides, registry, extensions.plugin_slots(registry))
    _fit_new_types(src, grid or {}, registry, extensions.plugin_slots(registry))
    _relabel(src, path)
    scenario = validate_source(src, registry, path, extensions)
    if anchor_file_settings(src, scenario, path):  # a base file's relative paths, made absolute from its folder
        scenario = validate_source(src, registry, path, extensions)
    return LoadedScenario(scenario, (origin or path).resolve(), src)


def _relabel(src: Source, path: Path) -> None:
    """Show marks relative to the working directory when that is shorter."""
    cwd = Path.cwd()
    files: dict[str, str | None] = {}  # each file's name as shown (None: as it is), found once (not once a mark)

    def shorter(file: str) -> str | None:
        p = Path(file)
        if p.is_absolute():
            try:
                return str(p.relative_to(cwd))
            except ValueError:
                return None
        return None

    def short(m: Mark) -> Mark:
        if m.file not in files:
            files[m.file] = shorter(m.file)
        file = files[m.file]
        return m if file is None else Mark(file, m.line, m.col)

    src.key_marks = {k: short(v) for k, v in src.key_marks.items()}
    src.value_marks = {k: short(v) for k, v in src.value_marks.items()}
