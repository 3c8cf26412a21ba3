"""Why a run tracked badly, from its own record: when the worst joint's error is over a degree (a millimetre for a
sliding joint) rms, what the trace and the safety layer show happened to it — its torque at the limit, a safety stop,
a contact, a model with no inertia there — so a failed ``tracking_*`` verdict comes with its reason."""

from __future__ import annotations

from typing import Any

import numpy as np

from rehabkit.core.kinds.trace import Trace

POOR_DEG, POOR_M = 1.0, 0.001  # rms tracking error above which the run says why
AT_LIMIT = 0.999  # a torque this close to its effort limit was clipped


def tracking_causes(trace: Trace, model, trip: tuple[float, str] | None, first_contact: dict | None,
                    inertia: np.ndarray | None) -> dict[str, Any] | None:
    """The worst-tracked joint (rms over its own unit's threshold) and what the record says of it, or None.

    Args:
        trace: The run's control-rate record.
        model: The robot's :class:`~rehabkit.models.robot_model.RobotModel`.
        trip: When the safety layer tripped and by which rule, if it did.
        first_contact: The run's first contact (``safety.first_contact`` of the summary), if any.
        inertia: Each joint's inertia as its own torque meets it at the start, if the model has dynamics.
    """
    if not len(trace.t):
        return None
    turns = np.asarray(model.revolute, bool)
    err = trace.q_ref - trace.q
    kept = np.isfinite(err).all(axis=1)  # (steps with a joint reference: none where a controller makes its own)
    if not kept.any():
        return None
    scaled = np.where(turns, np.degrees(err[kept]) / POOR_DEG, err[kept] / POOR_M)  # (1.0: the threshold, any unit)
    rms = np.sqrt(np.mean(scaled**2, axis=0))
    j = int(np.argmax(rms))
    if not rms[j] > 1.0:
        return None
    err = np.where(kept[:, None], err, 0.0)
    unit, scale = ("deg", np.degrees(1.0)) if turns[j] else ("m", 1.0)
    k = int(np.nanargmax(np.abs(err[:, j])))
    t_max = float(trace.t[k])
    causes: list[tuple[float, str]] = []  # (when, what): said in the order they happened
    if trip is not None and trip[0] <= t_max:
        causes.append((trip[0], f"the safety layer stopped the robot at t={trip[0]:.3f} s ({trip[1]}): the reference "
                                "went on without it"))
    if first_contact is not None and first_contact["t"] <= t_max:
        causes.append((first_contact["t"], f"the robot touched something first at t={first_contact['t']:.3f} s "
                                           f"({first_contact['robot']} against {first_contact['other']})"))
    # a torque at its limit: this joint's, and the joints' whose limit came first (a shoulder that can't hold the
    # arm drags the others along: their errors are its)
    effort = model.limits.effort
    at_limit = np.abs(trace.tau) >= AT_LIMIT * effort
    before = at_limit[: k + 1]
    if before.any():
        first_k = int(np.argmax(before.any(axis=1)))
        for i in np.flatnonzero(before[first_k]):
            if i != j:
                causes.append((float(trace.t[first_k]), f"{model.joint_names[i]}'s torque was at its {effort[i]:g} "
                               f"{'N·m' if turns[i] else 'N'} limit from t={trace.t[first_k]:.3f} s "
                               f"({int(at_limit[:, i].sum())} control steps)"))
    if clipped := int(at_limit[:, j].sum()):
        first = float(trace.t[int(np.argmax(at_limit[:, j]))])
        causes.append((first, f"its torque was at its {effort[j]:g} {'N·m' if turns[j] else 'N'} limit in {clipped} "
                              f"control steps, from t={first:.3f} s"))
    if inertia is not None and inertia[j] < 1e-6:
        causes.append((np.inf, f"the model gives it {inertia[j]:.2g} {'kg·m²' if turns[j] else 'kg'} of inertia: "
                               "gains scaled by the inertia have no stiffness there"))
    if not causes:
        losses = model.dissipation
        units = ("N·m", "N·m·s/rad") if turns[j] else ("N", "N·s/m")
        declared = [f"{what} {v:g} {u}" for what, v, u in (("friction", losses.friction[j], units[0]),
                                                            ("damping", losses.damping[j], units[1])) if v > 0]
        fix = (f"its drive declares {' and '.join(declared)}, left to the gains: a feedforward that compensates them "
               "(joint-pd's inverse-dynamics), or stiffer gains" if declared else
               "stiffer gains, a higher bandwidth_hz, or the inverse-dynamics feedforward")
        causes.append((np.inf, f"no clipped torque, stop or contact: the controller's gains are low for this joint's "
                               f"load ({fix})"))
    causes.sort(key=lambda c: c[0])
    return {"joint": model.joint_names[j], "unit": unit, "rms": float(rms[j] * (POOR_DEG if turns[j] else POOR_M)),
            "max": float(abs(err[k, j]) * scale), "t_max": t_max, "causes": [text for _, text in causes]}
