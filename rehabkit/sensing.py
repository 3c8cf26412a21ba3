"""Public helpers for sensor plugins: Kalman filtering and smoothing, rigid-body estimation from accelerometer
arrays.

Each name loads its own module on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

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


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
