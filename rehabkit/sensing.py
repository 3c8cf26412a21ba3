"""Public helpers for sensor plugins: Kalman filtering and smoothing, rigid-body estimation from accelerometer
arrays.

Each name loads its own module on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rehabkit.estimation.kalman import ConstantRateModel, KalmanBank, rts_smooth
    from rehabkit.estimation.rigid_body import AccelerometerArray, AngularVelocityEKF

_FROM = {
    "rehabkit.estimation.kalman": ("ConstantRateModel", "KalmanBank", "rts_smooth"),
    "rehabkit.estimation.rigid_body": ("AccelerometerArray", "AngularVelocityEKF"),
}

__all__ = [
    "ConstantRateModel", "KalmanBank", "rts_smooth", "AccelerometerArray", "AngularVelocityEKF",
]


def __getattr__(name: str):
    for module, names in _FROM.items():
        if name in names:
            value = globals()[name] = getattr(importlib.import_module(module), name)
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
