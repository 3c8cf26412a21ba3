"""What the host measured of the robot link: deadline misses, tick lateness, round trips, dropped states, and the
bridge's holds through gaps in the commands."""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.metric import Metric
from rehabkit.core.safety.event import SafetyEvent
from rehabkit.hardware.link.protocol import STALE

METRICS = (
    Metric("link_ticks", "count", clock="wall", description="ticks the loop ran over the link"),
    Metric("deadline_misses", "count", clock="wall", description="ticks started after the next was due"),
    Metric("deadline_*", clock="wall", description="ticks started after the next was due (the share: _rate)"),
    Metric("states_dropped*", "count", clock="wall", description="states refused (late, out of order, forged, …)"),
    Metric("bridge_hold_at_s", "s", "wall", description="when the bridge held the robot on its own"),
    Metric("bridge_stale_holds", "count", clock="wall", description="gaps in the commands the bridge held through"),
    Metric("ticks_skipped_s", "s", "wall", description="timeline paused after host stalls"),
    Metric("rtt_*", "ms", "wall", description="round trip of a command and its state"),
)


def link_metrics(link) -> dict[str, float]:
    """The link's figures over the run (all wall-clock: they measure this host and network)."""
    late = np.array(link.lateness) * 1e3
    rtt = np.array(link.rtt) * 1e3
    out = {"link_ticks": float(link.ticks), "deadline_misses": float(link.misses),
           "deadline_miss_rate": link.misses / max(1, link.ticks),
           "states_dropped": float(sum(link.rx.dropped.values())),
           **{f"states_dropped_{why.replace('-', '_')}": float(n) for why, n in link.rx.dropped.items()}}
    if len(late):
        out.update({"tick_lateness_median_ms": float(np.median(late)),
                    "tick_lateness_p99_ms": float(np.percentile(late, 99)),
                    "tick_lateness_max_ms": float(late.max())})
    if link.held_at is not None:
        out["bridge_hold_at_s"] = link.held_at
    out["bridge_stale_holds"] = float(len(link.stale_holds))
    out["ticks_skipped_s"] = link.skipped_s
    if len(rtt):
        out.update({"rtt_median_ms": float(np.median(rtt)), "rtt_p99_ms": float(np.percentile(rtt, 99))})
    return out


def link_series(link) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per tick: lateness of the loop, and the newest round trip measured by then [ms]."""
    ticks = np.arange(len(link.lateness)) * link.timestep
    out = {"link/tick_lateness_ms": (ticks, np.array(link.lateness) * 1e3)}
    if link.rtt:
        idx = np.clip(np.array(link.rtt_at) - 1, 0, len(link.rtt) - 1)
        out["link/round_trip_ms"] = (ticks, np.array(link.rtt)[idx] * 1e3)
    return out


def note_stale(link, msg, t: float) -> None:
    """Holds through gaps in the commands, from the bridge's count of held ticks in a state received at task time
    ``t``: exact even when the states sent during a hold were lost or came too late (as after a stall of the host)."""
    ticks, link._held = (msg.held - link._held) % 0x10000, msg.held
    if ticks and not link._stale_open:  # (not before the state before it: a paused timeline is shorter)
        link.stale_holds.append([max(link._state_t, t - ticks * link.timestep), 0])
    if ticks or link._stale_open:
        link.stale_holds[-1][1] += ticks
    link._stale_open, link._state_t = bool(msg.status & STALE), t


def stale_interventions(link) -> list[SafetyEvent]:
    """The bridge's holds through gaps in the commands, as safety events."""
    out = []
    for start, ticks in link.stale_holds:
        ms = 1e3 * ticks * link.timestep
        out.append(SafetyEvent(start, "stale-command", None, ms, link.config.bridge_stale_ms,
                               f"t={start:.3f}s: no newer command for {link.config.bridge_stale_ms:g} ms: the "
                               f"bridge held the posture for {ms:.0f} ms, until the next one", {"held_ticks": ticks},
                               level="WARN"))
    return out
