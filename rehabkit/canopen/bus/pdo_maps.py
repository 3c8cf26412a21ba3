"""PDO maps written into a node by SDO, with canopen's ``PdoMap`` API, as a CANopen master configures them: every
other PDO of the node disabled, the ones given mapped synchronous (taken or sampled at every SYNC)."""

from __future__ import annotations

from collections.abc import Sequence

import canopen

from rehabkit.canopen.bus.pdo_codec import PdoCodec

Entries = Sequence[tuple[int, int, int]]  # (index, subindex, bits)


def write_maps(network: canopen.Network, node: canopen.RemoteNode, rpdos: Sequence[Entries],
               tpdos: Sequence[Entries]) -> tuple[list[PdoCodec], list[PdoCodec]]:
    """RPDO 1.. and TPDO 1.. of ``node`` mapped as given, the rest disabled; their frames' codecs. The TPDOs'
    frames are read by whoever subscribes to their COB-IDs (canopen's own per-variable decoding unsubscribed)."""
    node.rpdo.read()
    node.tpdo.read()
    for pdos in (node.rpdo, node.tpdo):
        for pdo in pdos.map.values():
            pdo.enabled = False
    for pdos, maps in ((node.rpdo, rpdos), (node.tpdo, tpdos)):
        for number, entries in enumerate(maps, start=1):
            pdo = pdos[number]
            pdo.clear()
            for index, sub, _ in entries:
                pdo.add_variable(index, sub)
            pdo.trans_type, pdo.enabled = 1, True  # synchronous, every SYNC
    node.rpdo.save()
    node.tpdo.save()
    for pdo in node.tpdo.map.values():
        network.unsubscribe(pdo.cob_id, pdo.on_message)
    return ([PdoCodec.of(node.rpdo[k]) for k in range(1, len(rpdos) + 1)],
            [PdoCodec.of(node.tpdo[k]) for k in range(1, len(tpdos) + 1)])
