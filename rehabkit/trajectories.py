"""Public helpers for planners and controllers: time laws and rest-to-rest timing of joint paths.

Each name loads its own module on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rehabkit.cspace.timing import RestToRestPath, rest_to_rest_durations
    from rehabkit.models.time_laws import PEAK_VELOCITY, quintic

_FROM = {
    "rehabkit.models.time_laws": ("PEAK_VELOCITY", "quintic"),
    "rehabkit.cspace.timing": ("RestToRestPath", "rest_to_rest_durations"),
}

__all__ = [
    "PEAK_VELOCITY", "quintic", "RestToRestPath", "rest_to_rest_durations",
]


def __getattr__(name: str):
    for module, names in _FROM.items():
        if name in names:
            value = globals()[name] = getattr(importlib.import_module(module), name)
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
