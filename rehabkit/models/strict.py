"""The base of every DSL model (here, at the bottom of the layers: robot descriptions use it too)."""

from __future__ import annotations

from typing import Annotated, Any, get_args

from pydantic import BaseModel, ConfigDict, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError


class _FileSetting:
    """Marks a setting that names a file (see :data:`FilePath`)."""

    def __repr__(self) -> str:
        return "FilePath"


FILE_SETTING = _FileSetting()
# A setting naming a file, relative to the scenario file that writes it: a base file's (``extends:``) relative
# path is made absolute from that file's folder by the loader, so it means the same file wherever it is extended.
FilePath = Annotated[str, FILE_SETTING]



class _SensorSetting:
    """Marks a setting that names one of the scenario's sensors (see :data:`SensorName`)."""

    def __repr__(self) -> str:
        return "SensorName"


SENSOR_SETTING = _SensorSetting()
# A setting naming one of the scenario's sensors (a controller reading a force-torque sensor by name): the run's
# setup checks that the scenario has it, and says so at the setting, with the nearest name, before anything runs.
SensorName = Annotated[str, SENSOR_SETTING]



def marked_settings(node: Any, marker: Any, loc: tuple = ()) -> list[tuple[tuple, str]]:
    """(key path, value) of every setting marked ``marker`` (:data:`FILE_SETTING`, :data:`SENSOR_SETTING`) in a
    validated model, through nested models, lists and mappings."""
    found: list[tuple[tuple, str]] = []
    if isinstance(node, BaseModel):
        for name, info in type(node).model_fields.items():
            value = getattr(node, name)
            if marker in info.metadata and isinstance(value, str):
                found.append(((*loc, name), value))
            else:
                found += marked_settings(value, marker, (*loc, name))
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            found += marked_settings(value, marker, (*loc, i))
    elif isinstance(node, dict):
        for key, value in node.items():
            found += marked_settings(value, marker, (*loc, key))
    return found


BOOLEAN = "a number is needed here, not a boolean (YAML reads yes/no/on/off/true/false as booleans)"


def _numbers_only(annotation: Any) -> bool:
    """A number type, or a list/tuple/optional of them, that takes no boolean anywhere."""
    if annotation in (float, int):
        return True
    kinds = [a for a in get_args(annotation) if a is not type(None) and a is not Ellipsis]
    return bool(kinds) and all(_numbers_only(a) for a in kinds)


QUOTED = "a number is needed here, not the text '{text}': write it without quotes"


def _quoted_number(value: Any) -> str | None:
    """A number written in quotes (``"8.5"``), which pydantic would quietly read as one; a JSON Schema validator
    (an editor) refuses it, and so does the loader."""
    for v in value if isinstance(value, (list, tuple)) else (value,):
        if isinstance(v, str):
            try:
                float(v)
            except ValueError:
                continue
            return v
    return None


def _has_bool(value: Any) -> bool:
    return isinstance(value, bool) or (isinstance(value, (list, tuple)) and any(isinstance(v, bool) for v in value))


class StrictModel(BaseModel):
    """Base of every DSL model: unknown keys are errors, not silently ignored; numbers are finite, never booleans
    (YAML reads ``yes``, ``no``, ``on``, ``off`` as booleans, and pydantic would take them as 1 and 0) and never
    text in quotes (``"8.5"``: pydantic would read it, a JSON Schema validator would not)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_booleans_for_numbers(cls, data: Any) -> Any:
        if isinstance(data, dict):
            numbers = {k: v for k, v in data.items()
                       if (f := cls.model_fields.get(k)) is not None and _numbers_only(f.annotation)}
            errors = [InitErrorDetails(type=PydanticCustomError("boolean_number", BOOLEAN), loc=(k,), input=v)
                      for k, v in numbers.items() if _has_bool(v)]
            errors += [InitErrorDetails(type=PydanticCustomError("quoted_number", QUOTED, {"text": text}), loc=(k,),
                                        input=v) for k, v in numbers.items() if (text := _quoted_number(v)) is not None]
            if errors:  # located at each such setting (a model validator: a field one would meet the union tags too)
                raise ValidationError.from_exception_data(cls.__name__, errors)
        return data
