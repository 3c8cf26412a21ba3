"""Public helpers for planners and controllers: time laws and rest-to-rest timing of joint paths.

Each name loads its own module on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

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


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
