"""A run's events for ``events.tsv``: each target shown and reached, each safety event and stop (its rule, joint,
value and limit), the task's own events; onsets in seconds from the motion files' first sample, each row with its HED
tag (HED 8.4.0, as the validator bundles it).
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from rehabkit.bids.run_folder import RunFolder

COLUMNS = ("onset", "duration", "trial_type", "target", "rule", "joint", "value", "limit", "units", "HED")
HED_VERSION = "8.4.0"
HED = {
    "target_shown": "Sensory-event, Visual-presentation, (Cue, Target)",
    "target_reached": "Agent-action, Participant-response, (Experiment-participant, (Reach, Target))",
    "safety_stop": "Agent-action, (Robotic-agent, Halt), (Warning, Unexpected)",
    "safety_intervention": "Agent-action, (Robotic-agent, Move)",
    "task_event": "Experiment-control",
}
SIDECAR = {
    "onset": {"Description": "time from the motion files' first sample", "Units": "s"},
    "duration": {"Description": "how long it lasted: a target until the next was shown (or the run ended), a "
                                "reach, a ramp or a clipping episode; 0 for an instant", "Units": "s"},
    "trial_type": {"Description": "what happened", "Levels": {
        "target_shown": "a movement began toward a target",
        "target_reached": "the hand got to the target and stayed (the outcome measures' time to target)",
        "safety_stop": "the safety layer tripped: the robot stopped (or yielded, retreated) by the rule named",
        "safety_intervention": "the safety layer acted without a trip: a ramp in or out, torque clipped, brakes",
        "task_event": "an event of the task (a stop, an e-stop pressed, a replan)"}},
    "target": {"Description": "the target's name in the scenario (n/a where the task gave it none)"},
    "rule": {"Description": "the safety rule (position, velocity, torque, interaction-force, keep-in, e-stop, "
                            "ramp-in, ramp-out, torque-clip, brakes, ...) or the task event's action"},
    "joint": {"Description": "the joint concerned, where one is"},
    "value": {"Description": "what was measured when the rule tripped (its units in the units column)"},
    "limit": {"Description": "the limit it broke (its units in the units column)"},
    "units": {"Description": "units of value and limit: deg, deg/s (a revolute joint), m, m/s (a prismatic joint, "
                             "the hand in a keep-in box), N.m, N, ms (a gap in the commands over the robot link)"},
}


def _units(rule: str, revolute: bool | None) -> tuple[str, float]:
    """The unit of a safety event's value and limit, and the factor from SI."""
    if rule == "position":
        return ("deg", math.degrees(1.0)) if revolute is not False else ("m", 1.0)
    if rule == "velocity":
        return ("deg/s", math.degrees(1.0)) if revolute is not False else ("m/s", 1.0)
    if rule in ("torque", "torque-clip"):
        return ("N.m", 1.0) if revolute is not False else ("N", 1.0)
    if rule == "interaction-force":
        return "N", 1.0
    if rule == "stale-command":  # (a gap in the commands the bridge held through, against its bridge_stale_ms)
        return "ms", 1.0
    return ("m", 1.0) if rule == "keep-in" else ("n/a", 1.0)


def _targets(run: RunFolder) -> list[tuple[str, set[tuple]]]:
    """The task's targets in the order it visits them (its ``sequence``, else as listed), each with what the bag
    shows of it: a point or a posture, rounded (``same_as`` followed)."""
    task = run.scenario.get("task") or {}
    targets = {t.get("name"): t for t in task.get("targets", []) if isinstance(t, dict)}
    out = []
    for name in task.get("sequence") or list(targets):
        seen, keys = targets.get(name, {}), set()
        for _ in range(len(targets)):
            if "same_as" not in seen or seen["same_as"] not in targets:
                break
            seen = targets[seen["same_as"]]
        if "position" in seen and not seen.get("frame"):
            keys.add(("point", *np.round(np.asarray(seen["position"], float), 6)))
        for key, k in (("joints_deg", math.radians(1.0)), ("joints_rad", 1.0)):
            if key in seen:
                keys.add(("joints", *np.round(np.asarray(seen[key], float) * k, 6)))
        out.append((str(name), keys))
    return out


def _shown(run: RunFolder, t_of) -> list[tuple[float, str]]:
    """(time [s of the run], target name) of each target shown, in time order: each named by the next of the task's
    targets (in the order it visits them) that it matches, so that a target ``same_as`` another keeps its name."""
    seen: list[tuple[float, tuple]] = []
    for topic, kind in (("/targets", "point"), ("/targets/pose", "pose")):
        for _, msg in run.bag.messages.get(topic, []):
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            p = msg.point if kind == "point" else msg.pose.position
            seen.append((t_of(stamp), ("point", *np.round([p.x, p.y, p.z], 6))))
    js = run.bag.streams.get("/targets/joint_states")
    if js is not None:
        for stamp, q in zip(js.stamps, js.values):
            seen.append((t_of(stamp), ("joints", *np.round(q, 6))))
    order, at, shown = _targets(run), 0, []

    def rank(key: tuple) -> int:  # (targets shown at one time: in the task's order — a plan's start point first)
        return next((j for j in range(len(order)) if key in order[j][1]), len(order))

    for t, key in sorted(seen, key=lambda x: (x[0], rank(x[1]))):
        j = next((j for j in range(at, len(order)) if key in order[j][1]), None)
        if j is None:
            j = next((j for j in range(len(order)) if key in order[j][1]), None)
        else:
            at = j + 1
        shown.append((t, order[j][0] if j is not None else "n/a"))
    return shown


def event_rows(run: RunFolder, first_ns: int) -> list[dict[str, Any]]:
    """The run's events, onsets from ``first_ns`` (the motion files' first sample), in time order."""
    def t_of(stamp: int) -> float:
        return (int(stamp) - run.start_ns) / 1e9

    t0 = t_of(first_ns)
    end = float(run.summary.get("metrics", {}).get("sim_time_s") or t_of(run.bag.streams["/joint_states"].stamps[-1]))
    rows: list[dict[str, Any]] = []

    def add(t: float, duration: float, kind: str, **cols) -> None:
        # (HED joins the rows of one onset into one event: each row's tags a group of its own, told apart by a label)
        tag = "_".join(re.sub(r"[^A-Za-z0-9_-]", "", str(cols[c])) for c in ("target", "rule", "joint")
                       if cols.get(c) not in (None, "n/a")) or kind
        rows.append({"onset": round(max(t - t0, 0.0), 6), "duration": round(max(duration, 0.0), 6),
                     "trial_type": kind, **cols, "HED": f"({HED[kind]}, Label/{tag})"})

    shown = _shown(run, t_of)
    for i, (t, name) in enumerate(shown):
        if i + 1 < len(shown) and shown[i + 1][0] <= t:  # (a target another replaced at once was never shown)
            continue
        following = [u for u, _ in shown[i + 1:] if u > t]
        add(t, (following[0] if following else end) - t, "target_shown", target=name)
    for reach in (run.summary.get("outcomes") or {}).get("reaches", []):
        ttt = reach.get("time_to_target_s")
        if reach.get("reached") and ttt is not None and math.isfinite(ttt):
            at = [name for u, name in shown if abs(u - reach["t0_s"]) < 1e-6]
            add(reach["t0_s"] + ttt, 0.0, "target_reached", target=at[-1] if at else "n/a")
    model = run.robot.model
    revolute = dict(zip(model.joint_names, (bool(r) for r in model.revolute)))
    safety = run.summary.get("safety") or {}
    trips = {(e["t"], e["rule"]) for e in safety.get("events", [])}
    acted = safety.get("interventions", [])
    said = {(e["t"], e["rule"]) for e in acted}
    for e in [*acted, *(e for e in safety.get("events", []) if (e["t"], e["rule"]) not in said)]:
        units, k = _units(e["rule"], revolute.get(e.get("joint")))
        data = e.get("data") or {}
        kind = "safety_stop" if (e["t"], e["rule"]) in trips else "safety_intervention"
        value, limit = (None if e.get(x) is None else round(e[x] * k, 6) for x in ("value", "limit"))
        add(e["t"], float(data.get("duration_s") or 0.0), kind, rule=e["rule"], joint=e.get("joint"), value=value,
            limit=limit, units=units if value is not None or limit is not None else None)
    for e in run.summary.get("events") or []:
        add(float(e["t"]), 0.0, "task_event", rule=e.get("action"))
    rows.sort(key=lambda r: r["onset"])
    seen: set[tuple] = set()
    return [r for r in rows if (r["onset"], r["HED"]) not in seen and not seen.add((r["onset"], r["HED"]))]
