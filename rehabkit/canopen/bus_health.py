"""What the host measured of the bus, for ``summary.json`` and the log: cycles, late steps and the holds through
them, missed TPDOs, EMCYs, the bus load, SYNC-to-last-TPDO latency (real time), and each drive's state changes and
EMCYs in words, as notes."""

from __future__ import annotations

import math

import numpy as np

from rehabkit.canopen.emcy_codes import describe
from rehabkit.core.kinds.metric import Metric
from rehabkit.core.safety.event import SafetyEvent

METRICS = (
    Metric("can_cycles", "count", clock="wall", description="SYNC cycles the loop ran on the bus"),
    Metric("can_late_cycles", "count", clock="wall", description="steps that came a cycle after their deadline"),
    Metric("can_hold_cycles", "count", clock="wall", description="cycles the bus held the posture, the loop late"),
    Metric("can_missed_tpdos", "count", clock="wall", description="drive cycles whose TPDOs did not come in time"),
    Metric("can_latency_*", "ms", "wall", description="SYNC to a cycle's last TPDO, wall clock"),
    Metric("can_emcy", "count", description="EMCY messages from the drives"),
    Metric("can_bus_load", description="share of the bitrate the cyclic traffic takes (worst-case bit stuffing)"),
    Metric("can_frames_traced", "count", clock="wall", description="frames written to the CAN trace"),
)


def bus_metrics(b) -> dict[str, float]:
    """The canopen backend ``b``'s figures over the run."""
    lat = np.array([x for x in b.latency if not math.isnan(x)]) * 1e3
    clock = b.clock
    out = {"can_cycles": float(b.cycles), "can_late_cycles": float(clock.late if clock is not None else 0),
           "can_hold_cycles": float(sum(c for _, c in clock.holds)) if clock is not None else 0.0,
           "can_missed_tpdos": float(b.master.missed_total), "can_emcy": float(len(b.master.emcys)),
           "can_bus_load": b.load.load, "can_frames_traced": float(b.bus.frames)}
    if len(lat) and b.realtime:
        out.update({"can_latency_median_ms": float(np.median(lat)),
                    "can_latency_p99_ms": float(np.percentile(lat, 99))})
    return out


def latency_series(b) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per cycle, SYNC to its last TPDO [ms] (real time only: on a lock-step bus it measures this process)."""
    if not b.realtime:
        return {}
    lat = np.array(b.latency[1:]) * 1e3
    return {"can_latency_ms": (np.arange(len(lat)) * b.period, lat)}


def hold_interventions(b) -> list[SafetyEvent]:
    """The cycles the host held the posture through, because the loop's step was late."""
    out = []
    for steps, cycles in b.clock.holds if b.clock is not None else ():
        t, ms = steps * b.period, 1e3 * cycles * b.period
        out.append(SafetyEvent(t, "stale-command", None, ms, 1e3 * b.period,
                               f"t={t:.3f}s: the loop's step was late: the bus's cycles held the posture for "
                               f"{ms:.0f} ms, until the next one", {"held_cycles": cycles}, level="WARN"))
    return out


class DriveNotes:
    """Each drive's state change and each EMCY, in words, into the run's notes (``note(t, text)``)."""

    def __init__(self, note, master):
        self.note, self.master = note, master
        self.restart()

    def restart(self) -> None:
        self._states, self._said = list(self.master.states), len(self.master.emcys)

    def say(self, t: float, realtime: bool) -> None:
        m = self.master
        if self.note is not None:
            for i, (old, new) in enumerate(zip(self._states, m.states, strict=True)):
                if old != new:
                    self.note(t, f"drive {m.ids[i]} ({m.names[i]}): {old} -> {new}")
            for when, node, code in m.emcys[self._said:]:
                self.note(t if realtime else when, f"drive {node} ({m.names[m.ids.index(node)]}) EMCY: "
                                                    f"{describe(code)}")
        self.restart()
