"""How every run on CiA 402 drives ends, however it ends (normally, by a safety stop, by a fault, by Ctrl-C): the
robot brought to rest and the drives left as the standards say, so that nothing they do afterwards surprises anyone.

1. The stop's reaction: in stop category 1 or 2 a quick stop (controlword 0x02), cycled until every joint is at
   rest on the drives' own deceleration (0x6085) or a drive's fault reaction has ended; in category 0 none.
2. The power stages off, by the transitions each drive's state has (CiA 402): from OPERATION ENABLED disable
   operation (0x07, to SWITCHED ON) then shutdown (0x06, to READY TO SWITCH ON); from QUICK STOP ACTIVE disable voltage
   (0x00, to SWITCH ON DISABLED). Brakes close as the power goes.
3. The watchdogs disarmed in the order that raises nothing: the drives' heartbeat consumer of the host (0x1016) is
   switched off while the host still beats; the SYNC stops only once no drive is powered (a drive watches its SYNC only
   while it drives its joint).
4. NMT pre-operational (or stopped, as configured): no PDO is taken or sent any more.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable

import can
import canopen
import numpy as np

from rehabkit.canopen.cia402 import DISABLE_OPERATION, DISABLE_VOLTAGE, QUICK_STOP_CMD, SHUTDOWN, State
from rehabkit.canopen.config import DriveFaultError

AT_REST = 0.01  # [rad/s] a joint this slow is at rest
POWERED = {State.OPERATION_ENABLED.name, State.QUICK_STOP_ACTIVE.name, State.FAULT_REACTION_ACTIVE.name}
OFF_CYCLES = 10  # cycles the power stages are given to go off
ENDED = (can.CanError, DriveFaultError, canopen.SdoAbortedError, canopen.SdoCommunicationError)


def bring_to_rest(master, cycle: Callable[[np.ndarray], object], category: int, decel: np.ndarray,
                  period_s: float) -> None:
    """Steps 1 and 2 (see the module's doc) with ``cycle`` (one paced cycle of the bus), ``decel`` each joint's
    quick stop deceleration [rad/s²]."""
    zero = np.zeros(len(master.remotes))
    if not any(s in POWERED for s in master.states):
        return
    if category > 0:
        master.controlword[:] = QUICK_STOP_CMD
        longest = float(np.max(np.abs(master.qd) / np.maximum(decel, 1e-9)))
        for k in range(math.ceil((longest + 0.1) / period_s) + 2):
            cycle(zero)
            on = [s in POWERED for s in master.states]
            if k and all(not p or abs(v) < AT_REST for p, v in zip(on, master.qd, strict=True)) and \
                    State.FAULT_REACTION_ACTIVE.name not in master.states:
                break
    for _ in range(OFF_CYCLES):
        master.controlword[:] = [DISABLE_VOLTAGE if s == State.QUICK_STOP_ACTIVE.name else
                                 DISABLE_OPERATION if s == State.OPERATION_ENABLED.name else
                                 SHUTDOWN if s == State.SWITCHED_ON.name else master.controlword[i]
                                 for i, s in enumerate(master.states)]
        cycle(zero)
        if not any(s in POWERED or s == State.SWITCHED_ON.name for s in master.states):
            break


def release(master, nmt: str = "PRE-OPERATIONAL") -> None:
    """Steps 3 and 4: each node's heartbeat consumer of the host off, then NMT ``nmt`` (every node answering what
    it can: a silent one is left as it is)."""
    for r in (*master.remotes, *master.sensors):
        with contextlib.suppress(*ENDED, KeyError):
            r.sdo[0x1016][1].raw = 0
    for r in (*master.remotes, *master.sensors):
        with contextlib.suppress(*ENDED):
            r.nmt.state = nmt
