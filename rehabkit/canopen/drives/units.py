"""A drive's units, as the drive declares them, against its joint's SI units.

CiA 402 gives each object its unit: positions (0x607A, 0x6064, 0x607D) in position units, velocities (0x60FF,
0x606C, 0x607F) in velocity units, the quick stop deceleration (0x6085) in acceleration units, the max motor speed
(0x6080) as the motor's speed, torques (0x6071, 0x6077, 0x6072) in per mille of the rated torque (0x6076, the
motor's, mN·m). The drive says what its units are:

- the factor group: position factor = encoder resolution (0x608F: increments per motor revolution) × gear ratio
  (0x6091: motor revolutions per shaft revolution) / feed constant (0x6092: feed per shaft revolution) internal
  increments per position unit — a group left at its 1:1 defaults (or not there) keeps position units = increments;
- SI units (0x60A9 velocity, 0x60AA acceleration): prefix (byte 3, a signed power of ten), numerator (byte 2) and
  denominator (byte 1) unit codes (CiA 303-2): maxon's and Nanotec's 0x00B44700 is rev/min. Without 0x60A9 velocities
  are position units per second, accelerations velocity units per second; the max motor speed without it is in rpm,
  the profile's unit for it.

The scenario's ``encoder_counts`` and ``gear_ratio`` say what an increment and a motor turn are at the joint.
"""

from __future__ import annotations

import math
from dataclasses import replace

from rehabkit.canopen.bus.drive_dictionary import DriveDictionary
from rehabkit.canopen.config import DriveUnits

# CiA 303-2 unit codes: what one of each is in motor revolutions (numerators) or seconds (denominators)
# (0xC0: rev/min as one unit, maxon's numerator of rpm/s: 0x60AA = 0x00C00300)
RPM = 0xC0
REVOLUTIONS = {0xB4: 1.0, 0x10: 1 / (2 * math.pi), 0x41: 1 / 360.0, RPM: 1 / 60.0}  # rev, rad, degree, rpm
SECONDS = {0x03: 1.0, 0x47: 60.0, 0x48: 3600.0}  # s, min, h
UNIT_NAMES = {0xB4: "rev", 0x10: "rad", 0x41: "°", 0xC0: "rpm", 0x03: "s", 0x47: "min", 0x48: "h"}


class UnitsError(ValueError):
    """A drive declares a unit rehabkit cannot convert: ``index`` the object, ``value`` what it holds."""

    def __init__(self, what: str, index: int, value: int):
        self.what, self.index, self.value = what, index, value
        super().__init__(what)


def si_unit(value: int, index: int) -> tuple[float, float, str]:
    """An SI unit object's (0x60A9, 0x60AA) scale: (motor revolutions per unit's numerator × 10^prefix, seconds per
    its denominator, the unit in words)."""
    prefix = (value >> 24 & 0xFF) - 256 * (value >> 31 & 1)
    num, den = value >> 16 & 0xFF, value >> 8 & 0xFF
    if num not in REVOLUTIONS or den not in SECONDS:
        raise UnitsError(f"0x{index:04X} = 0x{value:08X} declares a unit rehabkit does not convert (numerator code "
                         f"0x{num:02X}, denominator 0x{den:02X}; it knows rev, rad and ° per s, min and h)", index,
                         value)
    scale = 10.0**prefix
    words = (f"{scale:g} " if prefix else "") + f"{UNIT_NAMES[num]}/{UNIT_NAMES[den]}"
    return REVOLUTIONS[num] * scale, SECONDS[den], words


def _ratio(d: DriveDictionary, index: int) -> float:
    """sub1 / sub2 of a factor-group object, 1 where it is not there or not given (0, none)."""
    a, b = d.value(index, 1), d.value(index, 2)
    return a / b if a and b else 1.0


def declared_units(units: DriveUnits, d: DriveDictionary) -> DriveUnits:
    """``units`` (the scenario's: increments and motor turns at the joint) with the drive's declared position,
    velocity, acceleration and motor-speed scales."""
    factor = _ratio(d, 0x608F) * _ratio(d, 0x6091) / _ratio(d, 0x6092) if d.has(0x6092, 1) else 1.0
    position = units.counts_per_rad / factor  # position units per joint radian
    motor_turns = units.gear_ratio / _ratio(d, 0x6091) / (2 * math.pi)  # shaft turns per joint radian
    declared = d.value(0x60A9)
    if declared:
        revs, seconds, words = si_unit(declared, 0x60A9)
        velocity = motor_turns / revs * seconds  # velocity units per joint rad/s
        motor_speed = velocity
    else:
        velocity, words = position, "position units/s"
        motor_speed = motor_turns * 60.0  # rpm
    accel = velocity
    accel_words = f"{words}/s"
    declared_accel = d.value(0x60AA)
    if declared_accel:
        revs, seconds, accel_words = si_unit(declared_accel, 0x60AA)
        accel = motor_turns / revs * seconds  # (a velocity unit per second: Nanotec's rev/min, maxon's rpm/s)
        if declared_accel >> 16 & 0xFF != RPM:  # (a numerator of rpm and a denominator of s: already per second)
            accel_words += "/s"
    return replace(units, position_per_rad=position, velocity_per_rad_s=velocity, accel_per_rad_s2=accel,
                   motor_speed_per_rad_s=motor_speed, velocity_unit=words, accel_unit=accel_words)


def units_of(spec, effort_nm: float, eds: str) -> DriveUnits:
    """A scenario's drive (``spec``: a :class:`~rehabkit.canopen.config.DriveSpec`) in the units its EDS/DCF ``eds``
    declares (what simulated drives serving that file use, as the master reads them from the drive)."""
    from rehabkit.canopen.bus.drive_dictionary import read_dictionary

    return declared_units(spec.units(effort_nm), read_dictionary(eds, spec.node_id))
