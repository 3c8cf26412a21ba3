"""Validating a merged scenario: plugin types checked against the registry first (with suggestions), then the whole
document by the pydantic model built from the installed plugins and the extensions' sections; each pydantic error is
mapped back to the longest key path the YAML actually has, at its file, line and column."""

from __future__ import annotations

import re
import types
import typing
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from rehabkit.core.kinds.names import nearest
from rehabkit.core.plugins.lifecycle import Extensions, default_extensions
from rehabkit.core.plugins.registry import PluginError, PluginRegistry
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError
from rehabkit.core.scenario.models import DEFAULT_BACKEND, PLUGIN_SECTIONS, ScenarioBase, scenario_model
from rehabkit.core.scenario.source import KeyPath, Source, _dotted

REQUIRED_PLUGIN_SECTIONS = ("robot", "planner", "controller")  # (backend: mujoco by default)


def _locate(src: Source, loc: Iterable[Any], key: bool) -> tuple[KeyPath, Mark]:
    """Longest prefix of ``loc`` the YAML has (pydantic adds union tags the YAML lacks).

    Errors about a whole section (its value is a mapping or list) point at its key.
    """
    path: KeyPath = ()
    node: Any = src.data
    for part in loc:
        # (the data must have it too: an extended file's marks outlive a list the extending file replaced)
        present = part in node if isinstance(node, dict) else (
            isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node))
        if (*path, part) in src.value_marks and present:
            path = (*path, part)
            node = node[part]
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


def _describe(err: dict[str, Any]) -> tuple[str, str]:
    """A pydantic error's message and, for a misspelt choice, its fix (the nearest choices)."""
    msg, fix = err["msg"], ""
    if err["type"] not in ("missing", "extra_forbidden") and "input" in err:
        value = err["input"]
        if not isinstance(value, (dict, list)):
            msg += f" (got {value!r})"
            if err["type"] == "literal_error" and isinstance(value, str):  # a misspelt choice: the nearest
                choices = re.findall(r"'([^']*)'", err.get("ctx", {}).get("expected", ""))
                fix = nearest(value, choices)
    return msg, fix


def _check_plugin_types(src: Source, registry: PluginRegistry, slots: dict[tuple[str, str], str]) -> list[Diagnostic]:
    """Unknown or missing plugin ``type`` values, with the closest installed names; the named plugins imported
    (only those: the scenario's model is built from them), a broken or conflicting one reported where named."""
    problems: list[Diagnostic] = []
    if not isinstance(src.data.get("backend"), dict):  # the default backend
        registry.find("backend", DEFAULT_BACKEND)
    for section in REQUIRED_PLUGIN_SECTIONS:
        if section not in src.data:
            problems.append(Diagnostic(src.value_marks[()], section, f"missing required field '{section}'"))
    sections: list[tuple[KeyPath, str]] = [((s,), k) for s, k in PLUGIN_SECTIONS.items()]
    sensors = src.data.get("sensors")
    if isinstance(sensors, dict):
        sections += [(("sensors", name), "sensor") for name in sensors]
    for (name, key), kind in slots.items():  # a layer's section holding a plugin's settings (patient.model)
        held = src.data.get(name)
        if isinstance(held, dict) and key in held:
            sections.append(((name, key), kind))
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
                    "missing 'type'",
                    f"installed {kind} plugins: {', '.join(names)}",
                )
            )
        elif node["type"] not in names:
            tpath = (*path, "type")
            problems.append(
                Diagnostic(
                    src.value_marks.get(tpath, src.value_marks[()]),
                    _dotted(tpath),
                    f"unknown {kind} plugin '{node['type']}'",
                    nearest(str(node["type"]), names),
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


def validate_source(src: Source, registry: PluginRegistry, file: Path,
                    extensions: Extensions | None = None) -> ScenarioBase:
    """Validate merged data; raise :class:`ScenarioError` with every problem."""
    extensions = extensions or default_extensions()
    problems = _check_plugin_types(src, registry, extensions.plugin_slots(registry))
    model = scenario_model(registry, extensions)
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
            msg, fix = _describe(err)
            if err["type"] == "extra_forbidden":
                allowed = _fields_at(model, loc[:-1]) or []
                msg, fix = f"unknown field '{loc[-1]}'", nearest(str(loc[-1]), allowed)
            elif err["type"] == "missing" and isinstance(loc[-1], int):  # a fixed-length list one short
                msg = f"too few values: {loc[-1]} given, value {loc[-1] + 1} is missing"
                is_key = False
                path, mark = _locate(src, loc[:-1], key=False)
            elif err["type"] == "missing":
                msg = f"missing required field '{loc[-1]}'"
            # the path as the YAML spells it: pydantic's union tags (plugin names) left out
            shown = _dotted(path + (loc[-1],) if is_key and path[-1:] != (loc[-1],) else path) or _dotted(loc)
            problems.append(Diagnostic(mark, shown, msg, fix))
        if not problems:
            problems.append(Diagnostic(Mark(str(file), 0, 0), "", str(exc)))
    else:
        problems += _event_planner_problems(src, result)
    if problems:
        problems.sort(key=lambda d: (d.mark.file, d.mark.line, d.mark.col))
        raise ScenarioError(problems)
    return result


def _event_planner_problems(src: Source, scenario: ScenarioBase) -> list[Diagnostic]:
    """A replan event's ``planner:`` settings, checked against the scenario's planner as they will be merged."""
    out: list[Diagnostic] = []
    for i, ev in enumerate(scenario.task.events):
        base = ("task", "events", i, "planner")
        if ev.planner is None:
            continue
        if "type" in ev.planner:
            path, mark = _locate(src, (*base, "type"), key=True)
            out.append(Diagnostic(mark, _dotted((*base, "type")), "an event's planner settings are for the "
                                  f"scenario's planner ('{scenario.planner.type}')", "leave out 'type'"))
            continue
        model = type(scenario.planner)
        try:
            model.model_validate({**scenario.planner.model_dump(), **ev.planner})
        except ValidationError as exc:
            for err in exc.errors():
                loc = (*base, *err["loc"])
                unknown = err["type"] == "extra_forbidden"
                _, mark = _locate(src, loc, key=unknown)
                said = (f"unknown field '{loc[-1]}' of planner '{scenario.planner.type}'",
                        nearest(str(loc[-1]), list(model.model_fields))) if unknown else _describe(err)
                out.append(Diagnostic(mark, _dotted(loc), *said))
    return out
