"""A PDO's frame as one ``struct``: what the cyclic path packs and unpacks each cycle.

canopen configures the maps (written by SDO, read back from a dictionary); per cycle its ``PdoMap`` would decode
each mapped variable through the object dictionary on every access (~10 µs each, tens a cycle per drive). Once a map
is set its frame layout is fixed, so the cyclic path reads it in one ``unpack``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass


@dataclass(frozen=True)
class PdoCodec:
    """A mapped PDO: its COB-ID, the (index, subindex) of each entry in frame order, their packed layout."""

    cob_id: int
    keys: tuple[tuple[int, int], ...]
    layout: struct.Struct

    @classmethod
    def of(cls, pdo_map) -> PdoCodec:
        """From a canopen ``PdoMap`` as configured (whole-byte entries of fixed-size types)."""
        keys, fmt = [], "<"
        for var in pdo_map.map:
            od = var.od
            packer = od.STRUCT_TYPES.get(od.data_type)
            if packer is None or var.length != 8 * packer.size:
                raise ValueError(f"PDO 0x{pdo_map.cob_id:X}: entry 0x{var.index:04X}sub{var.subindex} is not a "
                                 "whole fixed-size value")
            keys.append((var.index, var.subindex))
            fmt += packer.format.lstrip("<>=!@")
        return cls(pdo_map.cob_id & 0x7FF, tuple(keys), struct.Struct(fmt))

    def pack(self, values: dict[tuple[int, int], int]) -> bytes:
        return self.layout.pack(*(values[k] for k in self.keys))

    def unpack_into(self, data: bytes, values: dict[tuple[int, int], int]) -> None:
        for k, v in zip(self.keys, self.layout.unpack_from(data), strict=True):
            values[k] = v
