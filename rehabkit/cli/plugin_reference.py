"""The reference of one plugin, from its own pydantic model and metric declarations (``rehabkit plugins --fields
NAME``): every setting with its type, default and description (units in brackets), nested settings (a DH table's
rows, a robot's joints) indented under theirs, and the metrics the plugin reports."""

from __future__ import annotations

import re
import typing
from typing import Any

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from rehabkit.models.strict import FILE_SETTING, SENSOR_SETTING


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """Pydantic models an annotation holds (``list[JointSpec]``, ``Pose | None``, …)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_in(arg)]


def _type_name(annotation: Any) -> str:
    text = getattr(annotation, "__name__", None) if isinstance(annotation, type) else None
    return text or re.sub(r"(?:\w+\.)+(\w+)", r"\1", str(annotation)).replace("NoneType", "None")


_BOUNDS = (("gt", ">"), ("ge", "≥"), ("lt", "<"), ("le", "≤"), ("min_length", "at least"), ("max_length", "at most"))


def _bounds(metadata: list) -> str:
    """A field's bounds as its model declares them (``gt=0, le=1`` → ``(> 0, ≤ 1)``), or nothing."""
    said = [f"{sign} {getattr(m, key)!r}" for m in metadata for key, sign in _BOUNDS
            if getattr(m, key, None) is not None]
    return f" ({', '.join(said)})" if said else ""


def field_lines(model: type[BaseModel], indent: str = "  ", seen: tuple[type, ...] = ()) -> list[str]:
    """One line per field of ``model`` (``name: type = default (bounds) — description``), nested models below
    theirs."""
    lines = []
    for name, f in model.model_fields.items():
        if name == "type":
            continue
        default = "required" if f.is_required() else (
            f"{f.default_factory()!r}" if f.default_factory is not None else
            "none" if f.default is None else repr(f.default) if f.default is not PydanticUndefined else "required")
        marked = [repr(m) for m in f.metadata if m in (FILE_SETTING, SENSOR_SETTING)]  # FilePath, SensorName
        text = f"{indent}{name}: {marked[0] if marked else _type_name(f.annotation)} = {default}{_bounds(f.metadata)}"
        if f.description:
            text += f" — {f.description}"
        lines.append(text)
        for sub in _models_in(f.annotation):
            if sub not in seen and sub is not model:
                lines.append(f"{indent}  ({sub.__name__}{': ' + sub.__doc__.splitlines()[0] if sub.__doc__ else ''})")
                lines += field_lines(sub, indent + "    ", (*seen, model))
    return lines


def plugin_reference(info: Any) -> str:
    """The whole reference of a registered plugin (:class:`rehabkit.core.plugins.types.PluginInfo`)."""
    lines = [f"{info.kind} '{info.name}' ({info.provider.package} {info.provider.version}) — {info.description}",
             "settings:"]
    lines += field_lines(info.config) or ["  (none)"]
    metrics = info.declared.metrics
    if metrics:
        lines.append("metrics it reports (for expect:):")
        lines += [f"  {m.name} [{m.unit}]{' (wall clock)' if m.clock == 'wall' else ''} — {m.description}"
                  for m in metrics]
    requires = info.declared.requires
    if requires:
        lines.append("needs of the robot or backend: " + ", ".join(getattr(r, "__name__", str(r)) for r in requires))
    return "\n".join(lines)
