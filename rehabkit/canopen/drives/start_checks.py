"""What a reset checks of the drives before the run may enable them: each answered (else :func:`unanswered`), none in
FAULT (unless a person has cleared the e-stop since), the joints where the run starts."""

from __future__ import annotations

import math

import numpy as np

from rehabkit.canopen.config import DriveFaultError
from rehabkit.canopen.emcy_codes import describe
from rehabkit.canopen.master import DriveMaster


def unanswered(master: DriveMaster, names: list[str], syncs: int) -> DriveFaultError:
    """The fault of drives that sent no TPDOs in answer to ``syncs`` SYNCs, naming them."""
    silent = [names[i] for i, got in enumerate(master.missed[: len(names)]) if got]
    return DriveFaultError(f"no TPDOs in answer to {syncs} SYNCs (from {', '.join(silent)})", observable=False)


def check_no_fault(master: DriveMaster, names: list[str], cleared: bool, latch_name: str) -> None:
    """No drive in FAULT, unless the e-stop was cleared by a person (the first run after it resets the fault)."""
    faulted = [i for i, s in enumerate(master.states) if s == "FAULT"]
    if faulted and not cleared:
        i = faulted[0]
        code = master.remotes[i].sdo[0x603F].raw
        raise DriveFaultError(f"is in FAULT ({describe(code)}): its fault is reset only once a person has cleared "
                              f"the robot's e-stop latch (`rehabkit estop clear {latch_name} --by NAME`)",
                              master.ids[i], names[i], code, observable=False)


def check_start_posture(master: DriveMaster, names: list[str], q0: np.ndarray, simulated: bool) -> None:
    """The joints the drives report within 1° of ``q0`` (simulated drives were placed there: else their units are not
    the scenario's; a real robot must be brought there first)."""
    off = np.abs(master.q - q0)
    if off.max() <= math.radians(1.0):
        return
    i = int(np.argmax(off))
    if simulated:
        raise DriveFaultError(f"placed at {np.degrees(q0[i]):.1f}°, the drive reports {np.degrees(master.q[i]):.1f}°: "
                              "its units differ from backend.drives' (encoder_counts, gear_ratio, direction; "
                              "`rehabkit drives --drives` takes the scenario's)", master.ids[i], names[i],
                              observable=False)
    raise DriveFaultError(f"the robot is not at the start posture (joint {names[i]} off by {np.degrees(off[i]):.1f}°): "
                          "bring it there first", observable=False)
