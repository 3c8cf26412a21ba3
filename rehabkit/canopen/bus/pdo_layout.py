"""What goes over the bus each cycle, and whether it fits: the PDO maps the canopen backend writes into every drive,
and the bus arithmetic of them at the control rate.

Per drive and cycle (cyclic synchronous torque): one RPDO from the host (controlword, target torque) and two TPDOs
back (statusword with the actual position; the actual velocity, with the actual torque if asked for); per cycle one
SYNC; each drive's and the host's heartbeats besides. A CAN 2.0A data frame of ``n`` bytes is ``47 + 8n`` bits,
plus stuff bits: at worst one every four bits of the ``34 + 8n`` the rule covers (Davis et al., "Controller Area
Network (CAN) schedulability analysis", Real-Time Systems 35, 2007): 55 bits for a SYNC, 135 for 8 bytes, 0.135 ms at
1 Mbit/s. The bus load is counted with that worst case: a map that only fits on luck is refused.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

# (index, subindex, bits) of each PDO's entries, in order
RPDO1 = ((0x6040, 0, 16), (0x6071, 0, 16))  # controlword, target torque [‰ of rated] (CST)
# CSP: controlword, target position [counts], torque offset [‰: the host's gravity compensation] (CSV's the same
# size, with the target velocity)
RPDO_CSP = ((0x6040, 0, 16), (0x607A, 0, 32), (0x60B2, 0, 16))
TPDO1 = ((0x6041, 0, 16), (0x6064, 0, 32))  # statusword, position actual value [counts]
TPDO2 = ((0x606C, 0, 32),)  # velocity actual value [counts/s]
TORQUE_ACTUAL = (0x6077, 0, 16)  # [‰ of rated], in TPDO2 when asked for
SENSOR_TPDO = ((0x7130, 1, 16), (0x7130, 2, 16), (0x7130, 3, 16))  # a three-axis sensor's inputs (CiA 404)
SYNC_BYTES, HEARTBEAT_BYTES = 0, 1
TARGET = {"cst": (0x6071, 0, 16), "csp": (0x607A, 0, 32), "csv": (0x60FF, 0, 32)}
TORQUE_OFFSET = (0x60B2, 0, 16)


def needed(d, mode: str, torque_actual: bool = False, controlword_by_pdo: bool = True) -> tuple[list, list]:
    """The (index, subindex, bits) a drive with dictionary ``d`` (a
    :class:`~rehabkit.canopen.bus.drive_dictionary.DriveDictionary`) must carry each cycle in ``mode``: host to drive
    (the controlword unless it goes by SDO, the target; CSP/CSV the torque offset where the drive can take it), drive
    to host (statusword, position and velocity actual, the torque actual when asked for); widths as ``d`` says."""
    def width(e):
        return (e[0], e[1], d.widths.get((e[0], e[1]), e[2]))

    rx = [RPDO1[0]] if controlword_by_pdo else []
    rx.append(TARGET[mode])
    if mode != "cst" and (0x60B2, 0) in d.mappable:  # (optional: without it the drive's own loop holds gravity)
        rx.append(TORQUE_OFFSET)
    tx = [*TPDO1, *TPDO2, *((TORQUE_ACTUAL,) if torque_actual else ())]
    return [width(e) for e in rx], [width(e) for e in tx]


def frame_bits(data_bytes: int) -> int:
    """A standard (11-bit id) data frame's length on the wire with worst-case bit stuffing [bits]."""
    covered = 34 + 8 * data_bytes
    return 47 + 8 * data_bytes + (covered - 1) // 4


def tpdo2(torque_actual: bool) -> tuple[tuple[int, int, int], ...]:
    return (*TPDO2, TORQUE_ACTUAL) if torque_actual else TPDO2


def pdo_bytes(entries: tuple[tuple[int, int, int], ...]) -> int:
    return sum(bits for _, _, bits in entries) // 8


@dataclass(frozen=True)
class BusLoad:
    """The bus's share taken by the run's cyclic traffic: ``bits_per_cycle`` (SYNC and the PDOs), heartbeats
    [bits/s], at ``rate_hz`` on ``bitrate``."""

    drives: int
    rate_hz: float
    bitrate: int
    bits_per_cycle: int
    heartbeat_bits_s: float
    sensors: int = 0
    shape: str | None = None  # (what each drive carries, where not the usual RPDO + 2 TPDOs)
    others_bits: int = 0  # (of bits_per_cycle: the PDOs the drives keep sending that the run does not use)

    @property
    def load(self) -> float:
        """The share of the bitrate used (1.0: the bus is full)."""
        return (self.bits_per_cycle * self.rate_hz + self.heartbeat_bits_s) / self.bitrate

    def crowded(self, above: float = 0.9) -> str | None:
        """What to say of a load that fits but leaves under a tenth of the bus free (an error frame, a retried one,
        an SDO mid-run: each late by the cycle's end), or None."""
        if self.load <= above:
            return None
        freed = (f"; the drives' own PDOs the run does not use take {self.others_bits} bits a cycle "
                 "(backend.other_pdos: disable frees them)") if self.others_bits else ""
        return (f"the CAN bus is {self.load:.1%} full at {self.rate_hz:g} Hz ({self.bits_per_cycle} bits a cycle, "
                f"worst-case stuffing): little room for an SDO or a retried frame{freed}")

    def highest_rate_hz(self, limit: float = 1.0) -> float:
        """The highest control rate at which the load stays within ``limit``."""
        return (limit * self.bitrate - self.heartbeat_bits_s) / self.bits_per_cycle

    def describe(self) -> str:
        """The arithmetic, as a person checks it."""
        sensors = f" + {self.sensors} sensors × TPDO" if self.sensors else ""
        each = self.shape or "RPDO + 2 TPDOs"
        own = f", {self.others_bits} of them the drives' own PDOs the run does not use" if self.others_bits else ""
        return (f"{self.drives} drives × ({each}){sensors} + SYNC = {self.bits_per_cycle} bits a cycle{own} "
                f"(worst-case bit stuffing) × {self.rate_hz:g} Hz + heartbeats {self.heartbeat_bits_s:.0f} bit/s = "
                f"{self.load:.0%} of {self.bitrate / 1e3:g} kbit/s")


def plans_load(plans: Sequence, rate_hz: float, bitrate: int, heartbeat_ms: float, drives: int,
               sensors: int = 0) -> BusLoad:
    """The bus load of the PDOs each node's plan (:class:`~rehabkit.canopen.bus.pdo_plan.PdoPlan`) uses, and of those
    it leaves the drive sending, at ``rate_hz``."""
    bits = frame_bits(SYNC_BYTES)
    for plan in plans:
        bits += sum(frame_bits(p.bytes) for p in (*plan.rx, *plan.tx))
        bits += plan.others_bits
    beats = (len(plans) + 1) * frame_bits(HEARTBEAT_BYTES) * 1e3 / heartbeat_ms
    shapes = {(len(p.rx), len(p.tx), bool(p.others)) for p in plans[:drives]}
    others = round(sum(p.others_bits for p in plans))
    return BusLoad(drives, rate_hz, bitrate, round(bits), beats, sensors,
                   shape=None if len(shapes) == 1 and next(iter(shapes))[:2] == (1, 2) else
                   "the PDOs each drive's EDS gives", others_bits=others)


def bus_load(drives: int, rate_hz: float, bitrate: int, torque_actual: bool = False,
             heartbeat_ms: float = 100.0, sensors: int = 0, following: int = 0) -> BusLoad:
    """The bus load of ``drives`` drives (``following`` of them on position or velocity targets: a longer RPDO) and
    ``sensors`` three-axis sensors mapped as :mod:`this module <rehabkit.canopen.bus.pdo_layout>` maps them."""
    per_drive = sum(frame_bits(pdo_bytes(p)) for p in (RPDO1, TPDO1, tpdo2(torque_actual)))
    longer = frame_bits(pdo_bytes(RPDO_CSP)) - frame_bits(pdo_bytes(RPDO1))
    per_cycle = drives * per_drive + following * longer + sensors * frame_bits(pdo_bytes(SENSOR_TPDO)) \
        + frame_bits(SYNC_BYTES)
    beats = (drives + sensors + 1) * frame_bits(HEARTBEAT_BYTES) * 1e3 / heartbeat_ms
    return BusLoad(drives, rate_hz, bitrate, per_cycle, beats, sensors)
