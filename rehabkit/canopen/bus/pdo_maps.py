"""A PDO plan (:mod:`~rehabkit.canopen.bus.pdo_plan`) written into a node by SDO with canopen's ``PdoMap`` API, as a
CANopen master configures a drive: each PDO the run uses mapped (where its mapping can be written) and made
synchronous (taken or sampled at every SYNC), every other PDO left as the drive has it."""

from __future__ import annotations

import canopen

from rehabkit.canopen.bus.drive_dictionary import NOT_VALID
from rehabkit.canopen.bus.pdo_codec import PdoCodec
from rehabkit.canopen.bus.pdo_plan import PdoPlan, PlannedPdo

SYNCHRONOUS = 1  # transmission type: every SYNC


def write_plan(network: canopen.Network, node: canopen.RemoteNode, plan: PdoPlan) -> tuple[list[PdoCodec],
                                                                                          list[PdoCodec]]:
    """The plan's PDOs configured in ``node``; their frames' codecs (RPDOs, TPDOs). The TPDOs' frames are read by
    whoever subscribes to their COB-IDs (canopen's own per-variable decoding, where it subscribed, unsubscribed)."""
    for slot in plan.disable:  # (backend.other_pdos: disable) the COB-ID's bit 31: the PDO is not valid
        record = (node.tpdo if slot.tx else node.rpdo)[slot.number].com_record
        record[1].raw = slot.cob_id | NOT_VALID
    rx = [_configure(node.rpdo[p.slot.number], p) for p in plan.rx]
    tx = [_configure(node.tpdo[p.slot.number], p) for p in plan.tx]
    for pdo in node.tpdo.map.values():
        if pdo.cob_id is not None and pdo.on_message in network.subscribers.get(pdo.cob_id, []):
            network.unsubscribe(pdo.cob_id, pdo.on_message)
    return rx, tx


def _configure(pdo, planned: PlannedPdo) -> PdoCodec:
    pdo.clear()
    for index, sub, _ in planned.entries:
        pdo.add_variable(index, sub)
    pdo.cob_id, pdo.trans_type, pdo.enabled = planned.cob_id, SYNCHRONOUS, True
    slot, comm, mapping = planned.slot, pdo.com_record, pdo.map_array
    if planned.configure:
        # CiA 301's order: the PDO invalid (COB-ID bit 31), its transmission type, the map emptied (sub0 = 0), its
        # entries, their number, the PDO valid again. (canopen's PdoMap.save counts an ARRAY map's entries by
        # reading sub0 back after emptying it, so it writes none on a drive that takes the 0: written here.)
        comm[1].raw = planned.cob_id | NOT_VALID
        if comm[2].od.writable:
            comm[2].raw = SYNCHRONOUS
        mapping[0].raw = 0
        for k, (index, sub, bits) in enumerate(planned.entries, start=1):
            mapping[k].raw = index << 16 | sub << 8 | bits
        mapping[0].raw = len(planned.entries)
        comm[1].raw = planned.cob_id
    else:  # a fixed mapping, used as it is: enabled and synchronous where the drive lets a master say so
        if comm[2].od.writable and slot.trans_type != SYNCHRONOUS:
            comm[2].raw = SYNCHRONOUS
        if not slot.enabled:
            comm[1].raw = planned.cob_id
    return PdoCodec.of(pdo)
