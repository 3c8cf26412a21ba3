"""What a drive's object dictionary says it has, as a master must know it before it configures the drive: its PDOs
(how many each way, their COB-IDs, which are enabled, whether their mapping can be changed, what they carry), which
objects can be mapped and how wide each is, the modes it supports (0x6502), the units it declares (the factor group
0x608F/0x6091/0x6092, SI units 0x60A9/0x60AA, the rated torque 0x6076) and which optional objects it has.

Read from the EDS/DCF (``validate``; a DCF's ``ParameterValue`` over the EDS's default, as canopen reads them), and
at a run from the drive itself over SDO where the file gives no value (:func:`read_live`). Each object is located in
its file (``where``: ``file:line``), so a refusal names the line that says it.
"""

from __future__ import annotations

import contextlib
import pickle
import re
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

NOT_VALID = 0x80000000  # a PDO's COB-ID bit 31: the PDO does not exist (is disabled)
PDO_COUNT = 512  # RPDO 1-512 at 0x1400-0x15FF (maps 0x1600-), TPDO at 0x1800-0x19FF (maps 0x1A00-)


@dataclass(frozen=True)
class PdoSlot:
    """One PDO as the dictionary has it: ``number`` (1-512), ``cob_id`` (without the valid bit; 0: none given),
    ``enabled``, ``trans_type``, ``event_timer_ms`` (0: none), ``entries`` ((index, subindex, bits) as mapped),
    ``configurable``: its mapping can be written (its map's sub0 writable), ``cob_writable``: its COB-ID can."""

    tx: bool
    number: int
    cob_id: int
    enabled: bool
    trans_type: int | None
    event_timer_ms: int
    entries: tuple[tuple[int, int, int], ...]
    configurable: bool
    cob_writable: bool
    max_entries: int

    @property
    def bits(self) -> int:
        return sum(b for _, _, b in self.entries)

    @property
    def name(self) -> str:
        return f"{'T' if self.tx else 'R'}PDO{self.number}"


@dataclass(frozen=True)
class DriveDictionary:
    """A drive's object dictionary as far as a master needs it (see the module's doc)."""

    path: str
    objects: frozenset[tuple[int, int]]
    widths: dict[tuple[int, int], int]  # bits of each fixed-size object
    mappable: frozenset[tuple[int, int]]
    writable: frozenset[tuple[int, int]]
    values: dict[tuple[int, int], int]  # what the file gives (a DCF's value, else the default); missing: unknown
    rpdos: tuple[PdoSlot, ...]
    tpdos: tuple[PdoSlot, ...]
    lines: dict[int, int] = field(default_factory=dict)  # object index → the line of its section in the file
    commissioned: tuple[int, int] | None = None  # a DCF's [DeviceComissioning] NodeID, and its line

    def has(self, index: int, subindex: int = 0) -> bool:
        return (index, subindex) in self.objects

    def value(self, index: int, subindex: int = 0) -> int | None:
        return self.values.get((index, subindex))

    def where(self, index: int) -> str:
        """``file:line`` of the object's section (or the file alone where it has none)."""
        name = Path(self.path).name
        return f"{name}:{self.lines[index]}" if index in self.lines else name

    @property
    def supported_modes(self) -> int | None:
        """0x6502's bits, where the file says them (None: read them from the drive)."""
        return self.value(0x6502)


def object_dictionary(path: str | Path, node_id: int):
    """A fresh copy of python-canopen's object dictionary of the EDS/DCF at ``path`` for node ``node_id`` (``$NODEID``
    resolved): the file parsed once per version of it, whatever the node. Its parser takes 5-65 ms a file (a vendor's
    file of 170 kB the most), a copy 0.3-0.7 ms, and a run on six drives of one file wants twelve (the master's nodes
    and the drives') for six node ids; each its own, as nodes add to theirs."""
    stat = Path(path).stat()
    od = pickle.loads(_parsed(str(path), stat.st_mtime_ns, stat.st_size))
    return od if node_id == _PARSED_AS else _for_node(od, node_id)


_PARSED_AS = 1  # the node id the file is parsed for; another's values are resolved from the file's text


@lru_cache(maxsize=64)
def _parsed(path: str, mtime_ns: int, size: int) -> bytes:
    import canopen

    return pickle.dumps(canopen.import_od(path, _PARSED_AS))  # (this process's own objects, read back by it alone)


def _for_node(od, node_id: int):
    """``od`` as canopen's parser makes it for ``node_id``: the only values that depend on the node are those whose
    text names ``$NODEID`` (COB-IDs: ``$NODEID+0x180``), resolved here from that text (kept by the parser) by the
    parser's own function, and the commissioned node id it sets (tests/test_canopen_eds.py compares the two)."""
    from canopen.objectdictionary.eds import _convert_variable

    if od.node_id == _PARSED_AS:  # (set from the node id asked for, where the file has [DeviceComissioning])
        od.node_id = node_id
    for index in od.indices:
        obj = od[index]
        for var in obj.subindices.values() if hasattr(obj, "subindices") else (obj,):
            for raw, resolved in (("default_raw", "default"), ("value_raw", "value")):
                text = getattr(var, raw, None)
                if isinstance(text, str) and "$NODEID" in text.replace(" ", "").upper():
                    with contextlib.suppress(ValueError):  # (what the parser could not read it left unset)
                        setattr(var, resolved, _convert_variable(node_id, var.data_type, text))
    return od


def read_dictionary(path: str | Path, node_id: int = 1) -> DriveDictionary:
    """The dictionary of the EDS/DCF at ``path`` for node ``node_id`` (``$NODEID`` resolved), read once per version
    of the file."""
    stat = Path(path).stat()
    return _read(str(path), node_id, stat.st_mtime_ns, stat.st_size)


@lru_cache(maxsize=32)
def _read(path: str, node_id: int, mtime_ns: int, size: int) -> DriveDictionary:
    import warnings

    with warnings.catch_warnings():  # (vendors' files carry what canopen warns of and reads anyway)
        warnings.simplefilter("ignore")
        od = object_dictionary(path, node_id)
    return from_od(od, path)


def from_od(od, path: str = "") -> DriveDictionary:
    """The dictionary of canopen's ``ObjectDictionary`` ``od`` (what a RemoteNode holds)."""
    objects, widths, values, mappable, writable = set(), {}, {}, set(), set()
    for index in od.indices:
        obj = od[index]
        variables = [obj[s] for s in obj.subindices] if hasattr(obj, "subindices") else [obj]
        for var in variables:
            key = (index, var.subindex)
            objects.add(key)
            if var.fixed_size:
                widths[key] = 8 * var.STRUCT_TYPES[var.data_type].size if var.data_type in var.STRUCT_TYPES else 0
            given = var.value if var.value is not None else var.default
            if isinstance(given, int):
                values[key] = given
            if var.pdo_mappable:
                mappable.add(key)
            if var.writable:
                writable.add(key)
    rpdos = tuple(_slots(od, values, writable, tx=False))
    tpdos = tuple(_slots(od, values, writable, tx=True))
    return DriveDictionary(path, frozenset(objects), widths, frozenset(mappable), frozenset(writable), values, rpdos,
                           tpdos, _section_lines(path) if path else {}, _commissioned(path) if path else None)


def _commissioned(path: str) -> tuple[int, int] | None:
    """A DCF's node id as it was commissioned ([DeviceComissioning] NodeID), with its line: its absolute COB-IDs
    are that node's."""
    try:
        lines = Path(path).read_text(encoding="latin-1").splitlines()
    except OSError:
        return None
    section = ""
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if text.startswith("["):
            section = text.lower()
        elif section == "[devicecomissioning]" and text.lower().startswith("nodeid="):
            value = text.split("=", 1)[1].strip()
            try:
                return int(value, 0), number
            except ValueError:
                return None
    return None


# what a master reads from the drive itself where it configures it: the units and modes it declares
DECLARED = ((0x6502, 0), (0x608F, 1), (0x608F, 2), (0x6091, 1), (0x6091, 2), (0x6092, 1), (0x6092, 2), (0x60A9, 0),
            (0x60AA, 0), (0x6076, 0))


def read_live(od, upload, path: str = "") -> DriveDictionary:
    """The dictionary of a drive on the bus: its file's (``od``: canopen's, as its RemoteNode holds it) with the
    values the drive itself holds (``upload(index, subindex) -> int``, an SDO read; a refused read keeps the file's)
    for its PDOs' configuration and the units and modes it declares."""
    base = from_od(od, path)
    values = dict(base.values)
    keys = [k for k in DECLARED if k in base.objects]
    for slot in (*base.rpdos, *base.tpdos):
        comm, mapping = (0x1800 if slot.tx else 0x1400) + slot.number - 1, (0x1A00 if slot.tx else 0x1600) + \
            slot.number - 1
        keys += [(comm, 1), (comm, 2), (mapping, 0)]
        if (comm, 5) in base.objects:
            keys.append((comm, 5))
    for key in keys:
        _overlay(values, key, upload)
    for slot in (*base.rpdos, *base.tpdos):
        mapping = (0x1A00 if slot.tx else 0x1600) + slot.number - 1
        for sub in range(1, (values.get((mapping, 0)) or 0) + 1):
            if (mapping, sub) in base.objects:
                _overlay(values, (mapping, sub), upload)
    writable = set(base.writable)
    return replace(base, values=values, rpdos=tuple(_slots(od, values, writable, tx=False)),
                   tpdos=tuple(_slots(od, values, writable, tx=True)))


def _overlay(values: dict, key: tuple[int, int], upload) -> None:
    from canopen import SdoAbortedError

    with contextlib.suppress(SdoAbortedError):  # (the drive does not have what its file says: the file's stands)
        values[key] = upload(*key)


def _slots(od, values: dict, writable: set, tx: bool) -> list[PdoSlot]:
    base, maps = (0x1800, 0x1A00) if tx else (0x1400, 0x1600)
    slots = []
    for k in range(PDO_COUNT):
        comm, mapping = base + k, maps + k
        if comm not in od or mapping not in od:
            continue
        cob = values.get((comm, 1))
        count = values.get((mapping, 0)) or 0
        entries = []
        for sub in range(1, count + 1):
            raw = values.get((mapping, sub)) or 0
            if raw >> 16:
                entries.append((raw >> 16, raw >> 8 & 0xFF, raw & 0xFF))
        subs = [s for s in od[mapping].subindices if s] if hasattr(od[mapping], "subindices") else []
        slots.append(PdoSlot(tx, k + 1, (cob or 0) & 0x1FFFFFFF & ~0x40000000, cob is not None and not cob & NOT_VALID,
                             values.get((comm, 2)), values.get((comm, 5)) or 0, tuple(entries),
                             (mapping, 0) in writable and (mapping, 1) in writable, (comm, 1) in writable,
                             max(len(subs), 8) if (mapping, 0) in writable else len(subs)))
    return slots


def _section_lines(path: str) -> dict[int, int]:
    """Each object's ``[XXXX]`` section's line in the file (1-based)."""
    lines: dict[int, int] = {}
    header = re.compile(r"^\s*\[([0-9A-Fa-f]{4})\]\s*$")
    try:
        text = Path(path).read_text(encoding="latin-1")
    except OSError:
        return lines
    for number, line in enumerate(text.splitlines(), start=1):
        m = header.match(line)
        if m:
            lines.setdefault(int(m.group(1), 16), number)
    return lines
