"""One drive set up by SDO for a run, from what it says it has: its dictionary read from the drive (PDOs, units,
modes), the mode of operation checked against 0x6502 and read back from 0x6061, every limit written in the unit the
profile gives its object (converted through the units the drive declares: :mod:`~rehabkit.canopen.drives.units`), each
optional object only where the drive has it, and the PDOs the run needs planned and written
(:mod:`~rehabkit.canopen.bus.pdo_plan`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import canopen

from rehabkit.canopen.bus.drive_dictionary import DriveDictionary, read_live
from rehabkit.canopen.bus.pdo_layout import needed
from rehabkit.canopen.bus.pdo_plan import PdoPlan, PdoPlanError, plan_pdos
from rehabkit.canopen.config import DriveFaultError, DriveUnits
from rehabkit.canopen.drives.limits import DriveLimits, fitted
from rehabkit.canopen.drives.units import UnitsError, declared_units

MODE_CODE = {"csp": 8, "csv": 9, "cst": 10}  # modes of operation (0x6060): cyclic synchronous position/velocity/torque
MODE_BIT = {"csp": 7, "csv": 8, "cst": 9}  # their bits in 0x6502
MODE_NAMES = {"csp": "cyclic synchronous position", "csv": "cyclic synchronous velocity",
              "cst": "cyclic synchronous torque"}


@dataclass
class DriveSetup:
    """What a drive was set up as: its dictionary, units (as it declares them) and PDO plan, and what the set-up
    had to say (a limit more than its object holds, an optional object it lacks)."""

    dictionary: DriveDictionary
    units: DriveUnits
    plan: PdoPlan
    notes: list[str]


def interpolation_period(period_s: float) -> tuple[int, int]:
    """0x60C2: the cycle as value × 10^index s (value 0-255, index -3 to -6)."""
    for index in range(-3, -7, -1):
        value = period_s / 10.0**index
        if abs(value - round(value)) < 1e-6 and round(value) <= 255:
            return round(value), index
    raise ValueError(f"a cycle of {period_s:g} s is no whole number of microseconds up to 255")


def unsupported_mode(modes: int | None, mode: str) -> str | None:
    """Why a drive whose 0x6502 holds ``modes`` cannot run ``mode`` (None: it can, or does not say)."""
    if modes is None or modes >> MODE_BIT[mode] & 1:
        return None
    have = [name for name, bit in MODE_BIT.items() if modes >> bit & 1]
    return (f"the drive does not support {MODE_NAMES[mode]} (0x6502 = 0x{modes:08X}, bit {MODE_BIT[mode]} clear" +
            (f"; it has {', '.join(have)}" if have else "; it has no cyclic synchronous mode at all") + ")")


def set_up_drive(r: canopen.RemoteNode, path: str, name: str, units: DriveUnits, mode: str, limits: DriveLimits,
                 i: int, period_s: float, torque_actual: bool, read_rated: bool, controlword_by_pdo: bool = True,
                 keep_others: bool = True) -> DriveSetup:
    """Drive ``r`` (joint ``i``, ``name``) set up in pre-operational (see the module's doc)."""
    notes: list[str] = []
    sd = r.sdo

    def fault(what: str, code: int = 0) -> DriveFaultError:
        return DriveFaultError(what, r.id, name, code, observable=False)

    d = read_live(r.object_dictionary, lambda index, sub: _raw(r, index, sub), path)
    why = unsupported_mode(d.supported_modes, mode)
    if why:
        raise fault(why)
    try:
        units = declared_units(units, d)
    except UnitsError as exc:
        raise fault(exc.what) from None
    if read_rated and d.value(0x6076):  # the drive's own rated torque (the motor's [mN·m]), at the joint
        units = replace(units, rated_torque_nm=d.value(0x6076) * 1e-3 * units.gear_ratio)
    sd[0x6060].raw = MODE_CODE[mode]
    if d.has(0x6061) and sd[0x6061].raw != MODE_CODE[mode]:
        raise fault(f"0x6061 reads {sd[0x6061].raw} after 0x6060 was written {MODE_CODE[mode]} "
                    f"({MODE_NAMES[mode]}): the drive did not take the mode")
    if d.has(0x60C2, 1) and d.has(0x60C2, 2):
        value, index = interpolation_period(period_s)
        sd[0x60C2][1].raw, sd[0x60C2][2].raw = value, index
    _limits(r, d, units, limits, i, name, notes)
    try:
        rx, tx = needed(d, mode, torque_actual, controlword_by_pdo)
        if mode != "cst" and (0x60B2, 0) not in {(x, s) for x, s, _ in rx}:
            notes.append(f"drive {r.id} ({name}): it has no torque offset to map (0x60B2): the host's gravity "
                         "compensation does not reach it, its own position loop holds the arm's weight alone")
        plan = plan_pdos(d, r.id, rx, tx, period_s, keep_others)
    except PdoPlanError as exc:
        raise fault(exc.what) from None
    return DriveSetup(d, units, plan, notes)


def _raw(r: canopen.RemoteNode, index: int, sub: int) -> int:
    var = r.sdo[index] if not sub and not hasattr(r.object_dictionary[index], "subindices") else r.sdo[index][sub]
    return var.raw


def _limits(r: canopen.RemoteNode, d: DriveDictionary, u: DriveUnits, limits: DriveLimits, i: int, name: str,
            notes: list[str]) -> None:
    """Each limit the drive has an object for, in that object's unit: the position range (position units), the
    max motor speed (the motor's), the max profile velocity (velocity units), the quick stop deceleration
    (acceleration units), the max torque (per mille of the rated torque); the stop's option codes."""
    sd, od = r.sdo, r.object_dictionary
    if d.has(0x607D, 1) and d.has(0x607D, 2):
        scale = u.position * u.direction
        lo, hi = sorted((limits.lower[i] * scale, limits.upper[i] * scale))
        sd[0x607D][1].raw, sd[0x607D][2].raw = fitted(od[0x607D][1], lo, down=True)[0], fitted(od[0x607D][2], hi)[0]
    if d.has(0x6072):
        sd[0x6072].raw = fitted(od[0x6072], limits.torque[i] / u.rated_torque_nm * 1e3)[0]
    for obj, bound, factor, what, unit, theirs in (
            (0x6080, limits.speed[i], u.motor_speed, "max motor speed", "rad/s", "the motor's speed unit"),
            (0x607F, limits.speed[i], u.velocity, "max profile velocity", "rad/s", u.velocity_unit),
            (0x6085, limits.decel[i], u.acceleration, "quick stop deceleration", "rad/s²", u.accel_unit)):
        if not d.has(obj) or (obj, 0) not in d.writable:
            continue
        raw, clipped = fitted(od[obj], bound * factor)
        sd[obj].raw = raw
        if clipped:
            notes.append(f"drive {r.id} ({name}): its {what}, {bound:.4g} {unit}, is more than 0x{obj:04X} holds in "
                         f"{theirs} ({factor:.4g} per {unit}): told its largest, {raw / factor:.4g} {unit}")
    if d.has(0x605A):
        sd[0x605A].raw = limits.quick_stop_option
    if d.has(0x6007):  # (optional in the profile)
        sd[0x6007].raw = limits.abort_option
