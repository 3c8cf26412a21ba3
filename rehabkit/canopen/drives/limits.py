"""What each drive is told it may do: the run's limits as a backstop to the safety layer, and how it stops."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rehabkit.core.safety.stopping import joint_inertia, stop_decel
from rehabkit.hardware.bridge_limits import BridgeLimits

STOP_OPTION = {0: 0, 1: 2, 2: 6}  # stop category → quick stop option code (0x605A): off at once; ramp, then off; held
ABORT_OPTION = {0: 2, 1: 3, 2: 3}  # stop category → abort connection option code (0x6007): torque off; quick stop


@dataclass(frozen=True)
class DriveLimits:
    """What each drive is told it may do, in SI units at its joint (downloaded into 0x607D, 0x6080, 0x6072, 0x6085)."""

    lower: np.ndarray
    upper: np.ndarray
    speed: np.ndarray
    torque: np.ndarray
    decel: np.ndarray
    quick_stop_option: int
    abort_option: int = 1  # 0x6007: what a drive does when this host falls silent (1 fault, 2 torque off, 3 quick stop)

    @property
    def stop_category(self) -> int:
        """The stop category the quick stop option code stands for (what ends a run on these drives)."""
        return next(c for c, option in STOP_OPTION.items() if option == self.quick_stop_option)


def drive_limits(model, safety, q0: np.ndarray) -> DriveLimits:
    """The drives' own limits for robot ``model`` under the run's envelope ``safety`` (or None): its range and speed a
    margin wider than the safety layer's (a backstop, as the bridge's), its torques, the stop's deceleration (the
    envelope's, else half what each drive can give its joint at ``q0``, as the safety layer's) and category."""
    lim = model.limits
    wide = BridgeLimits(lim.lower, lim.upper, lim.velocity, revolute=model.revolute)
    decel = stop_decel(safety, model.revolute) if safety is not None else None  # (NaN: its kind's not set)
    if decel is None or np.isnan(decel).any():
        inertia = joint_inertia(model, q0)
        own = 0.5 * lim.effort / inertia if inertia is not None else lim.velocity * 4.0
        decel = own if decel is None else np.where(np.isnan(decel), own, decel)
    category = safety.category_of("e-stop") if safety is not None else 2
    return DriveLimits(wide._low, wide._high, wide._fast, lim.effort, decel, STOP_OPTION[category],
                       ABORT_OPTION[category])


def fitted(variable, value: float, down: bool = False) -> tuple[int, bool]:
    """``value`` rounded up (``down``: down) to a whole count, within what the object dictionary ``variable`` holds:
    its data type's range and the limits its EDS declares (LowLimit, HighLimit; its end where it holds less: then
    True). A light joint behind a fine encoder and a high gear can ask for more counts per s² than an UNSIGNED32
    holds; its largest then is the bound (4 × 10⁹ counts/s²)."""
    st = variable.STRUCT_TYPES[variable.data_type]
    bits = 8 * st.size
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if st.format[-1].islower() else (0, (1 << bits) - 1)
    if isinstance(variable.min, int):
        lo = max(lo, variable.min)
    if isinstance(variable.max, int):
        hi = min(hi, variable.max)
    v = math.floor(value) if down else math.ceil(value)
    return min(max(v, lo), hi), not lo <= v <= hi
