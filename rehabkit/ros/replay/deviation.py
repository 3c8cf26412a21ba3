"""How far a replay went from the session it replays: its largest deviation from the recorded joints — which joint,
how much (degrees for a revolute joint, metres for a prismatic one) and when. A session's bag holds them; a run's
folder where the run wrote its bag (``run.mcap``, ``--bag``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rehabkit.core.kinds.trace import Trace

RUN_BAG = "run.mcap"  # a run's own bag in its folder: its joints as they were


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


def run_deviation(run_dir: str | Path, replayed: Trace, per_joint: dict[str, dict]) -> list[dict] | None:
    """The replay's largest deviation (:func:`largest_deviation`) from the joints of the run in ``run_dir``, as its
    bag (:data:`RUN_BAG`) has them, resampled at the replay's control steps; None where the run wrote no bag. The
    replay's joints are its summary's ``per_joint`` (in the robot's order; a prismatic one's figures in metres:
    ``range_m``).

    Raises:
        BagError: the bag can't be read, or lacks one of the replay's joints.
    """
    from types import SimpleNamespace

    from rehabkit.ros.replay.bag_scenario import joint_order
    from rehabkit.ros.replay.session_bag import read_session

    bag = Path(run_dir) / RUN_BAG
    if not bag.exists():
        return None
    session = read_session(bag, roles=())
    names = list(per_joint)
    model = SimpleNamespace(joint_names=names, revolute=["range_m" not in figures for figures in per_joint.values()])
    t = np.asarray(replayed.t, float)
    t = t[t <= session.joints.t[-1] + 1e-9]
    q = session.joints.at(t)[:, joint_order(session, names)]
    zero = np.zeros_like(q)
    return largest_deviation(Trace(t, q, zero, zero, zero, zero), replayed, model)
