"""A run's outcome measures: its movements cut into reaches, then :mod:`rehabkit.rehab.outcomes` on each.

A reach is a plan's movement: from the plan's start to where the hand stays within
``tolerance_m`` of the plan's goal (or to the next plan). Per reach: SPARC of the
hand's speed, path-length ratio to the straight line, time to target. Over the run:
each joint's range of motion, the assistance ratio (the robot's positive work beyond
carrying its own weight, over that plus the person's), the peak interaction force at
the hand, and the safety layer's interventions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rehabkit.core.kinds.trace import Trace
from rehabkit.core.results.record import Movement
from rehabkit.models.hand_force import HandForce
from rehabkit.models.robot_model import RobotModel
from rehabkit.rehab.outcomes import (
    assistance_ratio,
    interaction_forces,
    path_length_ratio,
    range_of_motion,
    sparc,
    time_to_target,
)


def reach_outcomes(t: np.ndarray, hand: np.ndarray, reaches: list[Movement], dt: float, tolerance: float,
                   dwell: float, min_length: float) -> list[dict[str, Any]]:
    """Per-reach SPARC, path-length ratio and time to target; reaches shorter than ``min_length`` skipped."""
    out = []
    for r in reaches:
        k1 = min(r.k1, len(t))
        if k1 - r.k0 < 2:
            continue
        p0 = hand[r.k0]
        straight = float(np.linalg.norm(r.goal - p0))
        if straight < min_length:
            continue
        seg = hand[r.k0 : k1]
        ttt = time_to_target(t[r.k0 : k1], seg, r.goal, tolerance, dwell)
        end = r.k0 + (int(round(ttt / dt)) + 1 if np.isfinite(ttt) else k1 - r.k0)
        moved = hand[r.k0 : max(end, r.k0 + 2)]
        speed = np.linalg.norm(np.gradient(moved, dt, axis=0), axis=1)
        out.append({
            "t0_s": round(float(t[r.k0]), 6), "distance_m": straight, "time_to_target_s": ttt,
            "reached": bool(np.isfinite(ttt)), "sparc": sparc(speed, 1.0 / dt),
            "path_length_ratio": path_length_ratio(moved),
        })
    return out


def run_outcomes(trace: Trace, robot, reaches: list[Movement], dt: float, spec, interventions: int
                 ) -> tuple[dict[str, float], dict[str, Any]]:
    """Outcome metrics of a run (scalars for ``metrics``) and the per-reach and per-joint details.

    ``spec`` is the scenario's ``outcomes:`` section (target radius, dwell, shortest reach).
    """
    model: RobotModel = robot.model
    hand = trace.x if trace.x is not None else robot.fk_batch(trace.q)[:, :3, 3]
    per_reach = (reach_outcomes(trace.t, hand, reaches, dt, spec.tolerance_m, spec.dwell_s, spec.min_reach_m)
                 if len(trace.t) else [])

    def mean(key: str) -> float:
        values = [r[key] for r in per_reach if np.isfinite(r[key])]
        return float(np.mean(values)) if values else float("nan")

    rom = range_of_motion(trace.q) if len(trace.q) else np.zeros(model.dof)
    rom = np.where(model.revolute, np.degrees(rom), rom)  # (degrees for a revolute joint, metres for a prismatic)
    unit = ["deg" if r else "m" for r in model.revolute]
    person = trace.tau_h is not None and len(trace.t) and np.any(trace.tau_h)
    if person:
        own_weight = robot.gravity_torques(trace.q).reshape(trace.tau.shape)
        assist = assistance_ratio(trace.tau - own_weight, trace.tau_h, trace.qd, dt)
    else:  # nobody in the robot: whatever work was done, the robot did
        assist = 1.0 if len(trace.t) else float("nan")
    if trace.f_h is not None:  # measured: a force-torque sensor, an embodied person's largest cuff force
        magnitude = trace.f_h
    elif person:  # the hand force equivalent to the person's joint torques
        magnitude = np.linalg.norm(interaction_forces(HandForce(model).jacobians(trace.q), trace.tau_h), axis=1)
    else:
        magnitude = np.zeros(len(trace.t))
    metrics = {
        "reaches": float(len(per_reach)), "reaches_completed": float(sum(r["reached"] for r in per_reach)),
        "reaches_planned": float(len(reaches)),
        "sparc": mean("sparc"), "path_length_ratio": mean("path_length_ratio"),
        "time_to_target_s": mean("time_to_target_s"),
        "assistance_ratio": assist,
        "peak_interaction_force_n": float(magnitude.max()) if len(magnitude) else 0.0,
        "safety_interventions": float(interventions),
        **{f"rom_{unit[j]}_{name}": float(rom[j]) for j, name in enumerate(model.joint_names)},
    }
    details = {"reaches": per_reach, **{f"rom_{u}": {n: round(float(r), 4) for n, r, v in zip(
                   model.joint_names, rom, unit, strict=True) if v == u} for u in sorted(set(unit))},
               "interaction_force_n": magnitude}
    return metrics, details


def outcome_series(t: np.ndarray, details: dict[str, Any], every: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Time series for the log: the interaction force at the log rate, each reach's measures at its start."""
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    force = details["interaction_force_n"]
    if np.any(force):
        out["outcomes/interaction_force_n"] = (t[::every], force[::every])
    starts = np.array([r["t0_s"] for r in details["reaches"]], float)
    for key in ("sparc", "path_length_ratio", "time_to_target_s"):
        if len(starts):
            out[f"outcomes/{key}"] = (starts, np.array([r[key] for r in details["reaches"]], float))
    return out
