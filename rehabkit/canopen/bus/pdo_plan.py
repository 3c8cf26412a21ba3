"""Which of a drive's PDOs carry the run's process data, read from what its dictionary says it has: the objects a run
needs each cycle packed into the drive's own PDOs (at most 64 bits and its map's entries each), the lowest-numbered
ones whose mapping can be written first; a PDO whose mapping is fixed used as it is where it carries what is needed
(and, to the drive, nothing else). Every other PDO is left as the drive has it: the ones it keeps sending count in
the bus load. What cannot be planned is refused with the object and the file's line that says why
(:class:`PdoPlanError`: CiA 301's own reasons, "cannot be mapped", "number and length exceed the PDO").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rehabkit.canopen.bus.drive_dictionary import DriveDictionary, PdoSlot
from rehabkit.canopen.bus.pdo_layout import frame_bits

Entry = tuple[int, int, int]  # (index, subindex, bits)
NAMES = {0x6040: "controlword", 0x6041: "statusword", 0x6071: "target torque", 0x607A: "target position",
         0x60FF: "target velocity", 0x60B2: "torque offset", 0x6064: "position actual value",
         0x606C: "velocity actual value", 0x6077: "torque actual value", 0x7130: "analogue input"}
NOT_MAPPABLE = 0x06040041  # CiA 301's SDO abort: "object cannot be mapped to the PDO"
PREDEFINED = {False: 0x200, True: 0x180}  # CiA 301's predefined connection set: PDO k at base + 0x100 (k-1) + node


class PdoPlanError(ValueError):
    """The drive cannot carry the run's process data: ``index`` the object (0: none in particular), ``what`` why.
    ``objects``: every object it cannot carry (``index`` first; ``(index,)`` unless more are left without a PDO);
    ``where``: the ``file:line`` of the drive's file it points at ('' for none); ``abort``: the CiA 301 SDO abort
    code a drive answers the mapping with (0 for none)."""

    def __init__(self, what: str, index: int = 0, objects: tuple[int, ...] = (), where: str = "", abort: int = 0):
        self.what, self.index, self.where, self.abort = what, index, where, abort
        self.objects = tuple(objects) or ((index,) if index else ())
        super().__init__(what)


@dataclass(frozen=True)
class PlannedPdo:
    """A PDO the run uses: its slot as the drive has it, the entries it will carry, whether the run writes its
    mapping (``configure``), its COB-ID."""

    slot: PdoSlot
    entries: tuple[Entry, ...]
    configure: bool
    cob_id: int

    @property
    def bytes(self) -> int:
        return sum(b for _, _, b in self.entries) // 8


@dataclass(frozen=True)
class PdoPlan:
    """The RPDOs and TPDOs a run uses on one drive, and the drive's other TPDOs it leaves sending (``others``:
    (slot, frames per cycle))."""

    rx: tuple[PlannedPdo, ...]
    tx: tuple[PlannedPdo, ...]
    others: tuple[tuple[PdoSlot, float], ...]
    disable: tuple[PdoSlot, ...] = ()  # (the drive's PDOs the run turns off: backend.other_pdos: disable)

    @property
    def others_bits(self) -> float:
        """What the drive's own PDOs left sending add to a cycle [bits, worst-case stuffing]."""
        return sum(share * frame_bits(slot.bits // 8) for slot, share in self.others)


def entry(d: DriveDictionary, index: int, subindex: int = 0) -> Entry:
    """The object as a PDO entry: its width from the dictionary."""
    return index, subindex, d.widths.get((index, subindex), 0)


def _name(index: int) -> str:
    return f"0x{index:04X} ({NAMES[index]})" if index in NAMES else f"0x{index:04X}"


def check_mappable(d: DriveDictionary, needed: Sequence[Entry], tx: bool) -> None:
    """Each object in the dictionary and mappable the way it goes (else refused, located)."""
    for index, sub, bits in needed:
        if (index, sub) not in d.objects:
            whose = Path(d.path).name if d.path else "the drive's dictionary"
            raise PdoPlanError(f"{whose} has no {_name(index)}: the run maps it into a{' T' if tx else 'n R'}PDO "
                               "every cycle", index)
        if (index, sub) not in d.mappable:
            raise PdoPlanError(f"{_name(index)} cannot be mapped into a PDO (PDOMapping=0 at {d.where(index)}; "
                               f"CiA 301 abort 0x{NOT_MAPPABLE:08X})", index, where=d.where(index),
                               abort=NOT_MAPPABLE)
        if not bits or bits > 64:
            raise PdoPlanError(f"{_name(index)} is {bits} bits wide: no PDO carries it", index)


def plan_pdos(d: DriveDictionary, node_id: int, rx: Sequence[Entry], tx: Sequence[Entry],
              cycle_s: float = 0.001, keep_others: bool = True) -> PdoPlan:
    """The drive's PDOs carrying ``rx`` (host to drive) and ``tx`` (drive to host) every SYNC (see the module's
    doc); ``cycle_s`` the SYNC's period (what the drive's other, timed, TPDOs cost per cycle). ``keep_others``: the
    PDOs the run does not use left as the drive has them (else disabled, where their COB-ID can be written)."""
    check_mappable(d, rx, tx=False)
    check_mappable(d, tx, tx=True)
    planned_rx = _direction(d, node_id, list(rx), d.rpdos, tx=False)
    planned_tx = _direction(d, node_id, list(tx), d.tpdos, tx=True)
    used = {p.slot.number for p in planned_tx}
    others, disabled = [], []
    for slot in d.tpdos:
        if slot.number in used or not slot.enabled or not slot.cob_id:
            continue
        if not keep_others and slot.cob_writable:
            disabled.append(slot)
            continue
        others.append((slot, _frames_per_cycle(slot, cycle_s)))
    if not keep_others:
        used_rx = {p.slot.number for p in planned_rx}
        disabled += [s for s in d.rpdos if s.number not in used_rx and s.enabled and s.cob_id and s.cob_writable]
    return PdoPlan(tuple(planned_rx), tuple(planned_tx), tuple(others), tuple(disabled))


def _frames_per_cycle(slot: PdoSlot, cycle_s: float) -> float:
    """What a PDO the run leaves alone sends per cycle: synchronous every n-th SYNC; asynchronous at its event timer,
    or (none) as often as its values change: at worst every cycle."""
    t = slot.trans_type
    if t is not None and 1 <= t <= 240:
        return 1.0 / t
    if t == 0:  # (acyclic synchronous: at a SYNC when its values changed)
        return 1.0
    if slot.event_timer_ms:
        return min(1.0, cycle_s / (slot.event_timer_ms * 1e-3))
    return 1.0


def _direction(d: DriveDictionary, node_id: int, needed: list[Entry], slots: Sequence[PdoSlot],
               tx: bool) -> list[PlannedPdo]:
    planned: list[PlannedPdo] = []
    keys = {(i, s) for i, s, _ in needed}
    for slot in slots:  # fixed maps first: where one carries what is needed, it is used as it is
        if slot.configurable or not slot.entries or not slot.cob_id:
            continue
        carried = {(i, s) for i, s, _ in slot.entries}
        if not carried & keys or (not tx and not carried <= keys):  # (an RPDO writes every object it carries)
            continue
        if not slot.enabled and not slot.cob_writable:
            continue
        planned.append(PlannedPdo(slot, slot.entries, False, slot.cob_id))
        keys -= carried
    left = [e for e in needed if (e[0], e[1]) in keys]
    free = [s for s in slots if s.configurable and s.cob_writable and s.max_entries and (s.cob_id or s.number <= 4)]
    while left:
        if not free:
            what = ", ".join(_name(i) for i, _, _ in left)
            kind = "TPDO" if tx else "RPDO"
            have = sum(1 for s in slots if s.configurable)
            at = d.where(0x1A00 if tx else 0x1600)
            raise PdoPlanError(f"no {kind} left to carry {what}: the drive has {len(slots)} {kind}s, {have} of them "
                               f"with a mapping a master can write ({at})", left[0][0], tuple(e[0] for e in left), at)
        slot = free.pop(0)
        take, bits = [], 0
        for e in list(left):
            if bits + e[2] <= 64 and len(take) < slot.max_entries:
                take.append(e)
                bits += e[2]
                left.remove(e)
            else:
                break
        cob = slot.cob_id or PREDEFINED[tx] + 0x100 * (slot.number - 1) + node_id
        planned.append(PlannedPdo(slot, tuple(take), True, cob))
    return planned
