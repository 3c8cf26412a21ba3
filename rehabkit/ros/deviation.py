"""How far a replay went from the session it replays: its largest deviation from the recorded joints — which joint,
how much (degrees for a revolute joint, metres for a prismatic one) and when."""

from __future__ import annotations

import numpy as np

from rehabkit.core.results.metrics import Trace


def largest_deviation(recorded: Trace, replayed: Trace, model) -> list[dict]:
    """The largest ``|q_recorded - q_replayed|`` over the steps both have (their control steps from the session's
    start), among the revolute joints [deg] and, where ``model`` (a ``RobotModel``) has some, among the prismatic
    ones [m]: each ``{"joint", "value", "unit", "t_s"}``."""
    n = min(len(recorded.t), len(replayed.t))
    if n == 0:
        return []
    d = np.abs(np.asarray(recorded.q[:n], float) - np.asarray(replayed.q[:n], float))
    revolute = np.asarray(model.revolute, bool)
    names = list(model.joint_names)
    out = []
    for mask, unit, scale in ((revolute, "deg", np.degrees), (~revolute, "m", np.asarray)):
        if not mask.any():
            continue
        part = np.where(mask[None, :], np.nan_to_num(d, nan=np.inf), -1.0)
        k, j = np.unravel_index(int(np.argmax(part)), part.shape)
        out.append({"joint": names[j], "value": float(scale(d[k, j])), "unit": unit, "t_s": float(replayed.t[k])})
    return out


def said(deviations: list[dict]) -> str:
    """The deviations as a line: ``panda_joint3 by 0.012° at t = 2.900 s``, ``slide by 0.0003 m at ...``."""
    return "; ".join(f"{d['joint']} by {d['value']:.3g}{'°' if d['unit'] == 'deg' else ' m'} at t = {d['t_s']:.3f} s"
                     for d in deviations)
