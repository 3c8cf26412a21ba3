"""The scenario DSL as a JSON Schema (``rehabkit schema``) that editors and standard validators read as
``rehabkit validate`` does, where a schema can tell.

pydantic's own schema is the starting point, with three changes:

- **Plugin sections are keyed on ``type`` in plain JSON Schema.** pydantic marks them with OpenAPI's
  ``discriminator``, which JSON Schema validators ignore: they try every plugin's fields and report the
  "best" match of the wrong plugin. Here ``type`` is an ``enum`` of the installed plugins (a misspelt one is
  named as such) and ``if``/``then`` applies the named plugin's settings.
- **A file with ``extends:`` is partial.** Only the merged scenario must be whole: an extending file may leave
  out any section or setting and give ``null`` to delete an inherited one. Such a file is checked against a
  partial copy of every definition (nothing required, ``null`` allowed; unknown keys and wrong types still
  refused).
- **Sections an extension lets be a file** (``patient: patients/p01.yaml``) also accept a file path.
"""

from __future__ import annotations

import copy
from typing import Any

PARTIAL = "~partial"  # suffix of a definition's partial copy


def scenario_json_schema(model: type, file_sections: list[str]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of scenario files for the scenario ``model`` (``scenario_model``'s),
    ``file_sections`` being the top-level sections that may be given as a YAML file's path."""
    raw = model.model_json_schema()
    defs = {name: _keyed_on_type(d) for name, d in raw.pop("$defs", {}).items()}
    whole = _keyed_on_type(raw)
    for name in file_sections:
        prop = whole["properties"][name]
        if "anyOf" not in prop:
            prop["anyOf"] = [{k: prop.pop(k) for k in list(prop) if k not in ("default", "description")}]
        prop["anyOf"].append({"type": "string", "description": f"a YAML file holding the {name} section"})
    partial = _partial(whole)
    partial["properties"]["extends"] = {
        "description": "the scenario file(s) this one builds on, relative to this file; keys given here replace "
                       "or merge into theirs, null deletes one",
        "anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}, "minItems": 1}]}
    partial["required"] = ["extends"]
    all_defs = {**defs, **{name + PARTIAL: _partial(d) for name, d in defs.items()},
                "Scenario": whole, "PartialScenario": partial}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "rehabkit scenario",
        "description": "A scenario file: a whole scenario, or (with extends:) changes to the file(s) it extends.",
        "$defs": all_defs,
        "if": {"type": "object", "required": ["extends"]},
        "then": {"$ref": "#/$defs/PartialScenario"},
        "else": {"$ref": "#/$defs/Scenario"},
    }


def _keyed_on_type(node: Any) -> Any:
    """``node`` with every discriminated union (pydantic's ``oneOf`` + ``discriminator`` on ``type``) turned into
    a ``type`` enum and one ``if``/``then`` per plugin."""
    if isinstance(node, list):
        return [_keyed_on_type(n) for n in node]
    if not isinstance(node, dict):
        return node
    node = {k: _keyed_on_type(v) for k, v in node.items()}
    disc = node.get("discriminator")
    if not (isinstance(disc, dict) and disc.get("propertyName") == "type" and "oneOf" in node):
        return node
    mapping: dict[str, str] = disc["mapping"]
    out = {k: v for k, v in node.items() if k in ("default", "description", "title")}
    out.update({
        "type": "object",
        "required": ["type"],
        "properties": {"type": {"enum": sorted(mapping), "description": "which installed plugin"}},
        "allOf": [{"if": {"properties": {"type": {"const": name}}, "required": ["type"]},
                   "then": {"$ref": ref}} for name, ref in sorted(mapping.items())],
    })
    return out


def _partial(node: Any) -> Any:
    """The partial copy of a definition (see the module docstring): references to partial definitions, nothing
    required but a plugin's ``type`` inside its own ``if``, ``null`` allowed for every property."""
    if isinstance(node, list):
        return [_partial(n) for n in node]
    if not isinstance(node, dict):
        return node
    out: dict[str, Any] = {}
    for key, value in node.items():
        if key == "$ref" and isinstance(value, str) and value.startswith("#/$defs/"):
            out[key] = value + PARTIAL
        elif key == "required":
            continue
        elif key == "if":
            out[key] = copy.deepcopy(value)  # (which plugin: keeps its required type)
        elif key == "properties" and isinstance(value, dict):
            out[key] = {name: {"anyOf": [_partial(prop), {"type": "null"}]} for name, prop in value.items()}
        elif key == "additionalProperties" and isinstance(value, dict):  # (a mapping's entries: expect's bounds)
            out[key] = {"anyOf": [_partial(value), {"type": "null"}]}
        else:
            out[key] = _partial(value)
    return out
