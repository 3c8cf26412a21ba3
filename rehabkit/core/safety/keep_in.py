"""The envelope's keep-in box (``safety.keep_in``) as the safety layer watches it: world-frame corners, and where a
point leaves it."""

from __future__ import annotations

import numpy as np

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
