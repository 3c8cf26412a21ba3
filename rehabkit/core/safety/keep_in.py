"""The envelope's keep-in box (``safety.keep_in``) as the safety layer watches it: world-frame corners, where a
point leaves it, and the hand watched against it (:class:`KeepIn`)."""

from __future__ import annotations

import numpy as np

from rehabkit.core.safety.limit_breach import CHECK_DT

AXES = "xyz"


def world_box(box, base_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box's world corners (min, max): as written for ``frame: world``, else the world-aligned box around the
    base-frame box's corners (the hand is measured in the world)."""
    lo, hi = np.array(box.min, float), np.array(box.max, float)
    if box.frame == "base":
        corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
        w = corners @ base_pose[:3, :3].T + base_pose[:3, 3]
        lo, hi = w.min(axis=0), w.max(axis=0)
    return lo, hi


def plan_exit(t: float, trajectory, hand_world, box: tuple[np.ndarray, np.ndarray]) -> dict | None:
    """Where a plan made at ``t`` takes the hand out of ``box`` (its ``trajectory`` sampled every ``CHECK_DT``, the
    hand's world position ``hand_world(qs)``), said before it moves (the box is watched, not planned around): when,
    the axis and side, the bound and the message; else None."""
    ts = np.arange(0.0, trajectory.duration + 1e-9, CHECK_DT)
    found = box_exit(box, hand_world(trajectory.sample(ts)[0]))
    if found is None:
        return None
    k, a, side, bound = found
    message = (f"the plan made at t={t:.3f}s takes the hand out of the keep-in box ({AXES[a]} {side} {bound:g}) at "
               f"t={t + ts[k]:.3f}s: the safety layer will stop the robot there; move the target or the box")
    return {"t": round(t, 6), "at_s": round(t + float(ts[k]), 3), "axis": AXES[a], "side": side, "bound": bound,
            "message": message}


def box_exit(box: tuple[np.ndarray, np.ndarray], points: np.ndarray) -> tuple[int, int, str, float] | None:
    """The first of world ``points`` (n, 3) outside ``box``: (index, axis, "min"/"max", bound); None if all are in."""
    lo, hi = box
    out = (points < lo) | (points > hi)
    rows = np.flatnonzero(out.any(axis=1))
    if not len(rows):
        return None
    k = int(rows[0])
    a = int(np.argmax(out[k]))
    below = bool(points[k, a] < lo[a])
    return k, a, "min" if below else "max", float(lo[a] if below else hi[a])


class KeepIn:
    """The box watched: its world corners, and the hand's world position at a posture (``hand(q)``)."""

    def __init__(self, box, base_pose: np.ndarray, hand):
        if hand is None:
            raise ValueError("safety.keep_in needs the hand's position; the runner passes it")
        self.corners, self.hand = world_box(box, base_pose), hand

    def exit(self, q: np.ndarray) -> tuple[float, float, str, dict] | None:
        """Where the hand at ``q`` is outside the box: (its coordinate, the bound, what to say, the event's data); None
        inside (or not finite: the non-finite rule has that)."""
        x = self.hand(q)
        lo, hi = self.corners
        if (x >= lo).all() and (x <= hi).all():  # the every-step case, kept cheap
            return None
        found = box_exit(self.corners, x[None])
        if found is None:
            return None
        _, a, side, bound = found
        return (float(x[a]), bound, f"hand outside the keep-in box ({AXES[a]} {side})",
                {"axis": AXES[a], "side": side, "hand_m": np.round(x, 5).tolist()})
