"""A simulated device's object dictionary served as CiA 301 has a device serve it: a ``canopen.LocalNode`` (its SDO
server answers uploads and downloads) with the checks the library leaves to a device.

canopen's ``LocalNode`` already aborts a missing object (0x06020000), a missing sub-index (0x06090011), a write to a
read-only object (0x06010002) and a read of a write-only one (0x06010001). Here besides, on every download from a
master (CiA 301, table "SDO abort codes"):

- a length that does not match the object's type: 0x06070012 (too long) or 0x06070013 (too short);
- a value outside the EDS's LowLimit/HighLimit: 0x06090031 (too high) or 0x06090032 (too low);
- a PDO mapping entry (0x1600-0x17FF, 0x1A00-0x1BFF) naming a missing object, one its EDS says cannot be mapped
  (PDOMapping=0), a length other than the object's, or a read-only object into an RPDO: 0x06040041; a number of
  entries whose lengths add up to more than 64 bits: 0x06040042;
- whatever a device adds (:attr:`Device.checks`: e.g. a drive's supported modes).

No SDO is answered in NMT STOPPED (there a node answers only NMT and node guarding or heartbeat). What the EDS gives
no value for and the device must serve (a default map's number of entries, a drive's supported modes) is served from
:attr:`Device.served`; a reset restores a range of objects to their EDS/DCF values (:meth:`Device.restore`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import canopen
from canopen.objectdictionary import NUMBER_TYPES, ODArray, ODVariable
from canopen.sdo import SdoAbortedError

from rehabkit.canopen.bus.drive_dictionary import object_dictionary

NOT_MAPPABLE, PDO_TOO_LONG = 0x06040041, 0x06040042
TOO_LONG, TOO_SHORT = 0x06070012, 0x06070013
VALUE_TOO_HIGH, VALUE_TOO_LOW, INVALID_VALUE = 0x06090031, 0x06090032, 0x06090030
NO_DATA = 0x060A0023
RPDO_MAPS, TPDO_MAPS = range(0x1600, 0x1800), range(0x1A00, 0x1C00)

Check = Callable[[int, int, int], int | None]  # (index, subindex, value) → an abort code, or None: accepted


class Device(canopen.LocalNode):
    """Node ``node_id`` serving ``eds`` (an EDS or DCF: its ``ParameterValue``s served as the values) with ``extra``
    objects added to its dictionary (see the module's doc)."""

    def __init__(self, node_id: int, eds: Path | str, extra: Iterable[ODVariable] = ()):
        od = object_dictionary(eds, node_id)
        for var in extra:
            od.add_object(var)
        super().__init__(node_id, od)
        self.served: dict[tuple[int, int], int] = {}  # what it serves where neither a master nor its EDS set one
        self.checks: list[Check] = []
        for index in (*RPDO_MAPS, *TPDO_MAPS):
            if index in od:
                self._count_entries(index)

    def associate_network(self, network: canopen.Network) -> None:
        super().associate_network(network)
        # (its own SDO gate, and NMT handled by the device's NMT slave, not canopen's: see nmt_slave)
        network.unsubscribe(self.sdo.rx_cobid, self.sdo.on_request)
        network.unsubscribe(0, self.nmt.on_command)
        network.subscribe(self.sdo.rx_cobid, self._on_sdo)

    def _on_sdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        if self.nmt.state != "STOPPED":  # (CiA 301: no SDO in STOPPED)
            self.sdo.on_request(can_id, data, timestamp)

    def _count_entries(self, index: int) -> None:
        """A default map's number of entries as it maps them: the leading non-zero entries (an EDS may say 8 over
        eight zero entries, or give no number at all)."""
        record = self.object_dictionary[index]
        if 0 not in record:
            return
        entries = 0
        for sub in range(1, 256):
            if sub not in record or not self._stored(record[sub]):
                break
            entries = sub
        said = self._stored(record[0])
        self.served[index, 0] = entries if said is None else min(said, entries)

    @staticmethod
    def _stored(var: ODVariable) -> int | None:
        return var.value if var.value is not None else var.default

    def _find_object(self, index: int, subindex: int) -> ODVariable:
        obj = super()._find_object(index, subindex)
        parent = self.object_dictionary[index]
        if isinstance(parent, ODArray) and subindex not in parent.subindices:  # (canopen makes any sub of an array)
            raise SdoAbortedError(0x06090011)
        return obj

    def get_data(self, index: int, subindex: int, check_readable: bool = False) -> bytes:
        obj = self._find_object(index, subindex)
        if check_readable and not obj.readable:
            raise SdoAbortedError(0x06010001)
        for callback in self._read_callbacks:
            result = callback(index=index, subindex=subindex, od=obj)
            if result is not None:
                return obj.encode_raw(result)
        stored = self.data_store.get(index, {}).get(subindex)
        if stored is not None:
            return stored
        value = self.served.get((index, subindex), self._stored(obj))
        if value is None:
            raise SdoAbortedError(NO_DATA)
        return obj.encode_raw(value)

    def value(self, index: int, subindex: int = 0) -> int | None:
        """What it serves at (``index``, ``subindex``) as a number (None: nothing there)."""
        try:
            obj = self._find_object(index, subindex)
            return obj.decode_raw(self.get_data(index, subindex))
        except SdoAbortedError:
            return None

    def set_data(self, index: int, subindex: int, data: bytes, check_writable: bool = False) -> None:
        if check_writable:  # (a master's download: what CiA 301 has a device check)
            obj = self._find_object(index, subindex)
            if not obj.writable:
                raise SdoAbortedError(0x06010002)
            code = self._check(index, subindex, obj, bytes(data))
            if code:
                raise SdoAbortedError(code)
        super().set_data(index, subindex, data, check_writable)

    def _check(self, index: int, subindex: int, obj: ODVariable, data: bytes) -> int | None:
        if obj.data_type not in NUMBER_TYPES:
            return None
        if 8 * len(data) != len(obj):
            return TOO_LONG if 8 * len(data) > len(obj) else TOO_SHORT
        value = obj.decode_raw(data)
        if obj.max is not None and value > obj.max:
            return VALUE_TOO_HIGH
        if obj.min is not None and value < obj.min:
            return VALUE_TOO_LOW
        if index in RPDO_MAPS or index in TPDO_MAPS:
            code = self._check_map(index, subindex, value)
            if code:
                return code
        for check in self.checks:
            code = check(index, subindex, value)
            if code:
                return code
        return None

    def _check_map(self, index: int, subindex: int, value: int) -> int | None:
        """CiA 301's PDO mapping rules: each entry an object that can be mapped, the whole at most 64 bits."""
        if subindex == 0:
            bits = 0
            for sub in range(1, value + 1):
                entry = self.value(index, sub)
                if entry is None:
                    return VALUE_TOO_HIGH  # (more entries than the map has)
                bits += entry & 0xFF
            return PDO_TOO_LONG if bits > 64 else None
        if value == 0:  # (an unused entry)
            return None
        target, sub, bits = value >> 16, value >> 8 & 0xFF, value & 0xFF
        try:
            obj = self._find_object(target, sub)
        except SdoAbortedError:
            return NOT_MAPPABLE
        if 1 <= target <= 7:  # a dummy entry (the data type's index), where the EDS allows it
            return None if bits == len(obj) else NOT_MAPPABLE
        receiving = index in RPDO_MAPS
        if not obj.pdo_mappable or bits != len(obj) or not (obj.writable if receiving else obj.readable):
            return NOT_MAPPABLE
        return None

    def restore(self, low: int, high: int) -> None:
        """Every object from ``low`` to ``high`` back to its EDS/DCF value (what a reset does)."""
        for index in [i for i in self.data_store if low <= i <= high]:
            del self.data_store[index]
