"""YAML → validated scenario, with every error located at ``file:line:col``.

The YAML is composed once into nodes; each key path gets the mark of its key
and of its value. ``extends:`` files are merged underneath (deep merge; a
section whose plugin ``type`` changes is replaced, not merged), then
``--set a.b=value`` overrides on top. Plugin ``type`` names are checked against
the registry first (with suggestions), then the whole document is validated by
the pydantic model built from the installed plugins, and each pydantic error is
mapped back to the longest key path the YAML actually has.
"""

from __future__ import annotations

import copy
import types
import typing
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from rehabkit.core.names import suggest
from rehabkit.core.plugins import PluginError, PluginRegistry, default_registry
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.scenario.models import PLUGIN_SECTIONS, ScenarioBase, scenario_model

REQUIRED_PLUGIN_SECTIONS = ("robot", "planner", "controller")  # (backend: mujoco by default)

KeyPath = tuple[Any, ...]


@dataclass
class Source:
    """Raw scenario data and where each key path came from."""

    data: dict[str, Any]
    key_marks: dict[KeyPath, Mark]
    value_marks: dict[KeyPath, Mark]
    files: list[Path]


@dataclass
class LoadedScenario:
    """A validated scenario and its provenance."""

    model: ScenarioBase
    path: Path
    source: Source

    @property
    def directory(self) -> Path:
        return self.path.parent


def _mark(file: str, m: yaml.Mark) -> Mark:
    return Mark(file, m.line + 1, m.column + 1)


def read_yaml(path: Path) -> Source:
    """Parse one YAML file, keeping the position of every key and value."""
    name = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ScenarioError([Diagnostic(Mark(name, 0, 0), "", f"cannot read file: {exc.strerror}")]) from None
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            raise ScenarioError([Diagnostic(Mark(name, 1, 1), "", "the file is empty")])
        data = loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = _mark(name, exc.problem_mark) if exc.problem_mark else Mark(name, 0, 0)
        raise ScenarioError([Diagnostic(mark, "", f"YAML syntax: {exc.problem}")]) from None
    finally:
        loader.dispose()
    if not isinstance(data, dict):
        raise ScenarioError([Diagnostic(_mark(name, node.start_mark), "", "a scenario must be a mapping of sections")])

    key_marks: dict[KeyPath, Mark] = {}
    value_marks: dict[KeyPath, Mark] = {(): _mark(name, node.start_mark)}
    problems: list[Diagnostic] = []

    def walk(n: yaml.Node, path: KeyPath) -> None:
        if isinstance(n, yaml.MappingNode):
            seen: set[Any] = set()
            for k, v in n.value:
                key = k.value if isinstance(k, yaml.ScalarNode) else str(k.value)
                sub = (*path, key)
                if key in seen:
                    problems.append(
                        Diagnostic(
                            _mark(name, k.start_mark), _dotted(sub), "duplicate key (the later one would silently win)"
                        )
                    )
                seen.add(key)
                key_marks[sub] = _mark(name, k.start_mark)
                value_marks[sub] = _mark(name, v.start_mark)
                walk(v, sub)
        elif isinstance(n, yaml.SequenceNode):
            for i, v in enumerate(n.value):
                key_marks[(*path, i)] = value_marks[(*path, i)] = _mark(name, v.start_mark)
                walk(v, (*path, i))

    walk(node, ())
    if problems:
        raise ScenarioError(problems)
    return Source(data, key_marks, value_marks, [path])


def _dotted(path: Iterable[Any]) -> str:
    return ".".join(str(p) for p in path)


def deep_merge(base: Any, over: Any) -> Any:
    """``over`` on top of ``base``: mappings merge, everything else is replaced.

    A mapping whose ``type`` differs from the base's is a different plugin, so it
    replaces the base section instead of inheriting its keys. A key set to
    ``null`` in ``over`` removes the base's key.
    """
    if not (isinstance(base, dict) and isinstance(over, dict)):
        return copy.deepcopy(over)
    if "type" in over and base.get("type") not in (None, over["type"]):
        return copy.deepcopy(over)
    out = copy.deepcopy(base)
    for key, value in over.items():
        if value is None and key in out:
            del out[key]
        else:
            out[key] = deep_merge(out[key], value) if key in out else copy.deepcopy(value)
    return out


def _with_extends(path: Path, chain: tuple[Path, ...] = ()) -> Source:
    path = path.resolve()
    if path in chain:
        cycle = " -> ".join(str(p) for p in (*chain, path))
        raise ScenarioError([Diagnostic(Mark(str(path), 0, 0), "extends", f"circular extends: {cycle}")])
    src = read_yaml(path)
    parents = src.data.pop("extends", None)
    if parents is None:
        return src
    if isinstance(parents, str):
        parents = [parents]
    if not (isinstance(parents, list) and all(isinstance(p, str) for p in parents)):
        raise ScenarioError(
            [Diagnostic(src.value_marks[("extends",)], "extends", "expected a file path or a list of them")]
        )
    merged_data: dict[str, Any] = {}
    keys: dict[KeyPath, Mark] = {}
    values: dict[KeyPath, Mark] = {}
    files: list[Path] = []
    for i, parent in enumerate(parents):
        ppath = (path.parent / parent).resolve()
        if not ppath.exists():
            mark = src.value_marks.get(("extends", i), src.value_marks[("extends",)])
            raise ScenarioError([Diagnostic(mark, "extends", f"file not found: {ppath}")])
        base = _with_extends(ppath, (*chain, path))
        merged_data = deep_merge(merged_data, base.data)
        keys.update(base.key_marks)
        values.update(base.value_marks)
        files += base.files
    keys = {k: v for k, v in keys.items() if k != ("extends",)}
    keys.update(src.key_marks)
    values.update(src.value_marks)
    return Source(deep_merge(merged_data, src.data), keys, values, [*files, path])


def _with_profile(src: Source, path: Path) -> None:
    """``patient: some/profile.yaml`` → that file's mapping, its marks kept (errors point into the profile)."""
    ref = src.data.get("patient")
    if not isinstance(ref, str):
        return
    ppath = (path.parent / ref).resolve()
    if not ppath.exists():
        raise ScenarioError([Diagnostic(src.value_marks[("patient",)], "patient", f"profile not found: {ppath}")])
    prof = read_yaml(ppath)
    src.data["patient"] = prof.data
    for marks, theirs in ((src.key_marks, prof.key_marks), (src.value_marks, prof.value_marks)):
        marks.update({("patient", *k): m for k, m in theirs.items()})
    src.files.append(ppath)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"a.b.c=value"`` → (["a", "b", "c"], value parsed as YAML)."""
    if "=" not in text:
        raise ValueError(f"--set '{text}': expected key.path=value")
    key, _, raw = text.partition("=")
    parts = [p for p in key.strip().split(".") if p]
    if not parts:
        raise ValueError(f"--set '{text}': empty key")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ValueError(f"--set '{text}': value is not valid YAML ({exc})") from None
    return parts, value


def apply_overrides(src: Source, overrides: Iterable[str] | Mapping[str, Any]) -> None:
    """Apply ``--set`` style overrides in place; list items are addressed by index."""
    items = overrides.items() if isinstance(overrides, Mapping) else (parse_override(o) for o in overrides)
    for key, value in items:
        parts = key.split(".") if isinstance(key, str) else list(key)
        mark = Mark(f"<--set {'.'.join(parts)}>", 0, 0)
        node: Any = src.data
        path: KeyPath = ()
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if isinstance(node, list):
                if not (part.isdigit() and int(part) < len(node)):
                    raise ScenarioError(
                        [Diagnostic(mark, _dotted(parts), f"'{part}' is not an index of a list of {len(node)}")]
                    )
                part = int(part)
            elif not isinstance(node, dict):
                raise ScenarioError([Diagnostic(mark, _dotted(parts), f"'{_dotted(path)}' is not a mapping")])
            path = (*path, part)
            if last:
                node[part] = (
                    copy.deepcopy(value)
                    if not isinstance(node, dict) or not isinstance(node.get(part), dict)
                    else deep_merge(node[part], value)
                )
            else:
                if isinstance(node, dict) and part not in node:
                    node[part] = {}
                node = node[part]
            src.key_marks[path] = src.value_marks[path] = mark


def _plugin_kind(path: list[str]) -> str | None:
    """The plugin kind of a section path (``controller``, ``sensors.camera``, ``patient.model``), if it is one."""
    if len(path) == 1 and path[0] in PLUGIN_SECTIONS:
        return PLUGIN_SECTIONS[path[0]]
    return {("sensors",): "sensor", ("patient",): "patient"}.get(tuple(path[:1])) if len(path) == 2 else None


def _fit_new_types(src: Source, overrides: Iterable[str] | Mapping[str, Any], registry: PluginRegistry) -> None:
    """``--set controller.type=other``: settings the other plugin has no field for are dropped, with a warning.

    Shared settings stay (a planner's speed limits when switching planners); the new plugin's
    defaults fill the rest.
    """
    items = overrides.items() if isinstance(overrides, Mapping) else (parse_override(o) for o in overrides)
    for key, value in items:
        parts = key.split(".") if isinstance(key, str) else list(key)
        kind = _plugin_kind(parts[:-1]) if parts[-1:] == ["type"] else None
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


# ---------------------------------------------------------------------------
# Mapping validation errors back to the YAML
# ---------------------------------------------------------------------------


def _locate(src: Source, loc: Iterable[Any], key: bool) -> tuple[KeyPath, Mark]:
    """Longest prefix of ``loc`` the YAML has (pydantic adds union tags the YAML lacks).

    Errors about a whole section (its value is a mapping or list) point at its key.
    """
    path: KeyPath = ()
    node: Any = src.data
    for part in loc:
        if (*path, part) in src.value_marks:
            path = (*path, part)
            node = node[part] if isinstance(node, (dict, list)) else None
    key = key or isinstance(node, (dict, list))
    marks = src.key_marks if key and path in src.key_marks else src.value_marks
    return path, marks.get(path, src.value_marks[()])


def _unwrap(annotation: Any) -> list[Any]:
    """The concrete types an annotation can hold (through Annotated, Optional, Union)."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _unwrap(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType):
        return [t for a in typing.get_args(annotation) for t in _unwrap(a)]
    return [annotation]


def _fields_at(model: type[BaseModel], loc: tuple[Any, ...]) -> list[str] | None:
    """Field names of the model found by following ``loc`` from ``model``."""
    candidates: list[Any] = [model]
    for part in loc:
        nxt: list[Any] = []
        for c in candidates:
            origin = typing.get_origin(c)
            if isinstance(c, type) and issubclass(c, BaseModel):
                if part in c.model_fields:
                    nxt += _unwrap(c.model_fields[part].annotation)
                elif "type" in c.model_fields and part in typing.get_args(c.model_fields["type"].annotation):
                    nxt.append(c)  # a union tag naming this very model
            elif origin in (list, tuple) and isinstance(part, int):
                nxt += [t for a in typing.get_args(c) if a is not Ellipsis for t in _unwrap(a)]
            elif origin is dict:
                nxt += _unwrap(typing.get_args(c)[1])
        if nxt:
            candidates = [t for c in nxt for t in _unwrap(c)]
    models = [c for c in candidates if isinstance(c, type) and issubclass(c, BaseModel)]
    return sorted({f for m in models for f in m.model_fields if f != "type"}) if models else None


def _describe(err: dict[str, Any]) -> str:
    msg = err["msg"]
    if err["type"] not in ("missing", "extra_forbidden") and "input" in err:
        value = err["input"]
        if not isinstance(value, (dict, list)):
            msg += f" (got {value!r})"
    return msg


def _check_plugin_types(src: Source, registry: PluginRegistry) -> list[Diagnostic]:
    """Unknown or missing plugin ``type`` values, with the closest installed names; the named plugins imported
    (only those: the scenario's model is built from them), a broken or conflicting one reported where named."""
    problems: list[Diagnostic] = []
    if not isinstance(src.data.get("backend"), dict):  # the default backend
        registry.find("backend", "mujoco")
    for section in REQUIRED_PLUGIN_SECTIONS:
        if section not in src.data:
            problems.append(Diagnostic(src.value_marks[()], section, f"missing required field '{section}'"))
    sections: list[tuple[KeyPath, str]] = [((s,), k) for s, k in PLUGIN_SECTIONS.items()]
    sensors = src.data.get("sensors")
    if isinstance(sensors, dict):
        sections += [(("sensors", name), "sensor") for name in sensors]
    patient = src.data.get("patient")
    if isinstance(patient, dict) and "model" in patient:
        sections.append((("patient", "model"), "patient"))
    for path, kind in sections:
        node: Any = src.data
        for p in path:
            node = node.get(p) if isinstance(node, dict) else None
        if node is None:
            continue
        if not isinstance(node, dict):
            problems.append(
                Diagnostic(src.value_marks[path], _dotted(path), f"expected a mapping with a 'type' ({kind} plugin)")
            )
            continue
        names = registry.names(kind)
        if "type" not in node:
            problems.append(
                Diagnostic(
                    src.key_marks.get(path, src.value_marks[()]),
                    _dotted(path),
                    f"missing 'type'; installed {kind} plugins: {', '.join(names)}",
                )
            )
        elif node["type"] not in names:
            tpath = (*path, "type")
            problems.append(
                Diagnostic(
                    src.value_marks.get(tpath, src.value_marks[()]),
                    _dotted(tpath),
                    f"unknown {kind} plugin '{node['type']}'{suggest(str(node['type']), names)}",
                )
            )
        else:
            try:
                registry.get(kind, node["type"])
            except PluginError as exc:
                tpath = (*path, "type")
                problems.append(Diagnostic(src.value_marks.get(tpath, src.value_marks[()]), _dotted(tpath),
                                           f"{kind} plugin '{node['type']}' can't be used: {exc}"))
    return problems


def validate_source(src: Source, registry: PluginRegistry, file: Path) -> ScenarioBase:
    """Validate merged data; raise :class:`ScenarioError` with every problem."""
    problems = _check_plugin_types(src, registry)
    model = scenario_model(registry)
    try:
        result = model.model_validate(src.data)
    except ValidationError as exc:
        bad_sections = {d.path.split(".type")[0] for d in problems}
        for err in exc.errors():
            loc = tuple(err["loc"])
            if any(_dotted(loc).startswith(s) for s in bad_sections):
                continue  # already reported as an unknown plugin type
            is_key = err["type"] in ("extra_forbidden", "missing")
            path, mark = _locate(src, loc, key=is_key)
            msg = _describe(err)
            if err["type"] == "extra_forbidden":
                allowed = _fields_at(model, loc[:-1]) or []
                msg = f"unknown field '{loc[-1]}'{suggest(str(loc[-1]), allowed)}"
            elif err["type"] == "missing":
                msg = f"missing required field '{loc[-1]}'"
            # the path as the YAML spells it: pydantic's union tags (plugin names) left out
            shown = _dotted(path + (loc[-1],) if is_key and path[-1:] != (loc[-1],) else path) or _dotted(loc)
            problems.append(Diagnostic(mark, shown, msg))
        if not problems:
            problems.append(Diagnostic(Mark(str(file), 0, 0), "", str(exc)))
    if problems:
        problems.sort(key=lambda d: (d.mark.file, d.mark.line, d.mark.col))
        raise ScenarioError(problems)
    return result


def load_scenario(
    path: str | Path,
    overrides: Iterable[str] | Mapping[str, Any] = (),
    registry: PluginRegistry | None = None,
    origin: Path | None = None,
) -> LoadedScenario:
    """Read, merge, override and validate a scenario file.

    Args:
        path: The scenario YAML.
        overrides: ``["a.b=1", ...]`` as on the command line, or ``{"a.b": 1}``.
        registry: Plugins to validate against (default: the installed ones).
        origin: For a run's snapshot of a scenario: the file it was taken from (relative paths resolve
            from its folder, and the run reports it as its scenario).

    Raises:
        ScenarioError: with one :class:`Diagnostic` per problem.
    """
    path = Path(path)
    if not path.exists():
        raise ScenarioError([Diagnostic(Mark(str(path), 0, 0), "", "no such file")])
    registry = registry or default_registry()
    src = _with_extends(path)
    _with_profile(src, path)
    try:
        apply_overrides(src, overrides)
    except ValueError as exc:
        raise ScenarioError([Diagnostic(Mark("<--set>", 0, 0), "", str(exc))]) from None
    _fit_new_types(src, overrides, registry)
    _relabel(src, path)
    return LoadedScenario(validate_source(src, registry, path), (origin or path).resolve(), src)


def _relabel(src: Source, path: Path) -> None:
    """Show marks relative to the working directory when that is shorter."""
    cwd = Path.cwd()

    def short(m: Mark) -> Mark:
        p = Path(m.file)
        if p.is_absolute():
            try:
                return Mark(str(p.relative_to(cwd)), m.line, m.col)
            except ValueError:
                return m
        return m

    src.key_marks = {k: short(v) for k, v in src.key_marks.items()}
    src.value_marks = {k: short(v) for k, v in src.value_marks.items()}
