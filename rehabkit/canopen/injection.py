"""Faults injected into simulated drives (``backend.inject``), for tests and the fault table — never on a real bus
(``validate`` refuses them with one)."""

from __future__ import annotations

import can


def _bus_off(msg, timeout=None) -> None:
    raise can.CanOperationError("the CAN controller is bus-off (injected)")


def inject(b, fault) -> None:
    """Fault ``fault`` (an :class:`~rehabkit.canopen.config.Injection`) into the canopen backend ``b``'s bus, as the
    run reaches its time."""
    if fault.fault == "host-heartbeat":
        b.master.beating = False
        return
    if fault.fault == "host-stall":  # (real time only: validate refuses it on a lock-step bus)
        b.clock.pause(fault.for_s)  # the whole host stalls: no SYNC meanwhile
        return
    if fault.fault == "bus-off":  # its controller off the bus: every frame it is given fails, as python-can says
        b.bus.network.bus.send = _bus_off
        return
    node = fault.node or b.rig.drives[0].node.id
    drive = next(d for d in b.rig.drives if d.node.id == node)
    if fault.fault == "drive":
        drive.fault(fault.code)
    elif fault.fault == "drive-disabled":
        drive.machine.disable_locally()
    elif fault.fault == "drive-silent":
        drive.silent = True
    else:
        drive.heartless = True
