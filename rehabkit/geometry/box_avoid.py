"""Deterministic end-effector path around obstacles, over their box faces.

The method of the ARM record-and-replay planner: for the first obstacle the straight
segment enters, work in the box frame, take the entry and exit points, project each on
the four edges of its face, and keep the shortest path entry → edge point(s) → exit whose
consecutive points share a face; transform back. Every new segment is planned the same
way, so the cost grows with the number of obstacles actually met.

Cylinders and spheres are planned over their oriented bounding boxes (the paper's
suggested extension); the returned path is still checked against the true solids.

The paper reports wrong paths around overlapping obstacles: a detour over one box can run
into its neighbour, and the neighbour's detour back into the first. Here, when a box's
detours cannot be completed, it is merged with every box it overlaps into one enclosing
box and planning restarts; there are at most n − 1 merges. A path is returned only after
an exact segment-versus-solid check of every segment against every (margin-inflated)
obstacle; otherwise :class:`NoPathError` says why.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from rehabkit.geometry.solids import Box, Solid, _slab_interval, path_hits


class NoPathError(RuntimeError):
    """No collision-free path exists, or none is found by the deterministic method. ``end``: the end refused as it
    lies (``"start"`` or ``"goal"``), when that is why; then ``obstacle``: the obstacle it lies inside (its name), or
    None when it lies below the floor."""

    def __init__(self, message: str, end: str | None = None, obstacle: str | None = None):
        super().__init__(message)
        self.end, self.obstacle = end, obstacle


@dataclass(frozen=True)
class AvoidResult:
    path: np.ndarray  # (N, 3) polyline from start to goal
    merges: int  # how many times overlapping boxes were merged
    boxes: list[Box]  # the boxes the final path was planned over (after merges)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.path, axis=0), axis=1).sum())


class _BlockedError(Exception):
    def __init__(self, index: int) -> None:
        self.index = index


def _face_of(local: np.ndarray, half: np.ndarray) -> tuple[int, float]:
    k = int(np.argmax(np.abs(local) / half))
    return k, float(np.sign(local[k]) or 1.0)


Face = tuple[int, float]  # (axis, sign) in the box frame


def _edge_points(p: np.ndarray, face: Face, half: np.ndarray) -> list[np.ndarray]:
    """Projections of a face point on the four edges of its face."""
    out = []
    for j in range(3):
        if j == face[0]:
            continue
        for s in (-1.0, 1.0):
            q = p.copy()
            q[j] = s * half[j]
            out.append(q)
    return out


def _on_faces(p: np.ndarray, half: np.ndarray) -> set[tuple[int, float]]:
    tol = 1e-9 * max(1.0, float(half.max()))
    return {(k, s) for k in range(3) for s in (-1.0, 1.0) if abs(p[k] - s * half[k]) <= tol}


def surface_candidates(box: Box, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """Detours over the faces of ``box`` for segment a→b, shortest first, in world frame.

    Each candidate is the list of surface points [p_in, ..., p_out] (without a and b).
    Empty when the segment misses the box.
    """
    la, lb = box.to_local(a), box.to_local(b)
    interval = _slab_interval(la, lb, box.half)
    if interval is None:
        return []
    t_in, t_out = interval
    d = lb - la
    ends = []
    for t in (t_in, t_out):
        p = la + t * d
        face = _face_of(p, box.half)
        p[face[0]] = face[1] * box.half[face[0]]  # an endpoint inside the box is pushed to its nearest face
        ends.append((p, face))
    (p_in, f_in), (p_out, f_out) = ends
    paths: list[list[np.ndarray]] = []
    if f_in == f_out:
        paths.append([p_in, p_out])
    a_pts, b_pts = _edge_points(p_in, f_in, box.half), _edge_points(p_out, f_out, box.half)
    for q in a_pts:
        if f_out in _on_faces(q, box.half):
            paths.append([p_in, q, p_out])
    for qa, qb in itertools.product(a_pts, b_pts):
        if _on_faces(qa, box.half) & _on_faces(qb, box.half):
            paths.append([p_in, qa, qb, p_out])
    paths.sort(key=lambda pts: sum(float(np.linalg.norm(pts[i + 1] - pts[i])) for i in range(len(pts) - 1)))
    return [box.to_world(np.array(pts)) for pts in paths]


def _boxes_overlap(a: Box, b: Box) -> bool:
    """Separating-axis test for two oriented boxes (closed)."""
    axes = [a.rotation[:, i] for i in range(3)] + [b.rotation[:, i] for i in range(3)]
    axes += [np.cross(a.rotation[:, i], b.rotation[:, j]) for i in range(3) for j in range(3)]
    ca, cb = a.corners(), b.corners()
    for ax in axes:
        n = np.linalg.norm(ax)
        if n < 1e-12:
            continue
        pa, pb = ca @ ax, cb @ ax
        if pa.max() < pb.min() or pb.max() < pa.min():
            return False
    return True


def _enclosing(boxes: list[Box], frame: Box, name: str) -> Box:
    pts = np.vstack([frame.to_local(b.corners()) for b in boxes])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return Box(frame.to_world((lo + hi) / 2), (hi - lo) / 2, frame.rotation, name)


class _Router:
    def __init__(self, plan_boxes: list[Box], clearance: float, floor: tuple[np.ndarray, float] | None = None) -> None:
        self.plan = plan_boxes
        self.floor = floor
        self.budget = 40 * len(plan_boxes) + 40
        # "hit" boxes, stacked for vectorised tests: the plan boxes shrunk by half the clearance,
        # so segments lying on a plan box's faces do not count as entering it
        self._c = np.array([b.center for b in plan_boxes]).reshape(-1, 3)
        self._r = np.array([b.rotation for b in plan_boxes]).reshape(-1, 3, 3)
        self._h = np.array([b.half for b in plan_boxes]).reshape(-1, 3) - clearance / 2

    def first_hit(self, a: np.ndarray, b: np.ndarray) -> int | None:
        """Index of the hit box the segment a→b enters first (all boxes' slab tests at once)."""
        la = np.einsum("nij,ni->nj", self._r, a - self._c)
        d = np.einsum("nij,i->nj", self._r, b - a)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-self._h - la) / d
            t2 = (self._h - la) / d
        parallel = np.abs(d) < 1e-15
        lo = np.where(parallel, np.where(np.abs(la) <= self._h, -np.inf, np.inf), np.minimum(t1, t2))
        hi = np.where(parallel, np.where(np.abs(la) <= self._h, np.inf, -np.inf), np.maximum(t1, t2))
        t_in = np.maximum(lo.max(axis=1), 0.0)
        t_out = np.minimum(hi.min(axis=1), 1.0)
        hits = np.flatnonzero(t_in <= t_out)
        if hits.size == 0:
            return None
        return int(hits[np.argmin(t_in[hits])])

    def containing(self, p: np.ndarray) -> int | None:
        """Index of a hit box containing point ``p``, or None."""
        local = np.einsum("nij,ni->nj", self._r, p - self._c)
        inside = np.flatnonzero(np.all(np.abs(local) <= self._h, axis=1))
        return int(inside[0]) if inside.size else None

    def inside_any(self, pts: np.ndarray) -> bool:
        local = np.einsum("nij,kni->knj", self._r, pts[:, None, :] - self._c[None])
        return bool(np.any(np.all(np.abs(local) <= self._h[None], axis=2)))

    def below_floor(self, pts: np.ndarray) -> bool:
        """Whether any point lies on the wrong side of the floor plane (no detour goes under the floor)."""
        return self.floor is not None and bool(np.any(np.asarray(pts) @ self.floor[0] < self.floor[1] - 1e-12))

    def route(self, a: np.ndarray, b: np.ndarray, depth: int) -> list[np.ndarray]:
        i = self.first_hit(a, b)
        if i is None:
            return [a, b]
        self.budget -= 1
        if self.budget < 0 or depth > len(self.plan) + 2:
            raise _BlockedError(i)
        blamed = i
        for cand in surface_candidates(self.plan[i], a, b):
            if self.inside_any(cand) or self.below_floor(cand):
                continue
            pts = [a, *cand, b]
            try:
                out = [a]
                for p, q in zip(pts[:-1], pts[1:], strict=True):
                    out.extend(self.route(p, q, depth + 1)[1:])
                return out
            except _BlockedError as err:
                blamed = err.index if err.index != i else blamed
                if self.budget < 0:
                    break
        raise _BlockedError(i if blamed == i else blamed)


def _escape(p: np.ndarray, router: _Router, solids: list[Solid], label: str) -> list[np.ndarray]:
    """Points leading from ``p`` out of every planning box it lies in.

    A point outside the inflated obstacles can still lie inside a planning box: in the
    clearance shell, in the corners of a sphere's or cylinder's bounding box, or inside
    the enclosing box of merged overlapping obstacles (e.g. beside a cup standing on a
    tray). It leaves along one box axis, to the nearest face whose straight step touches
    no inflated obstacle and stays above the floor.
    """
    pts = [p]
    for _ in range(len(router.plan) + 1):
        inside = router.containing(pts[-1])
        if inside is None:
            return pts
        box = router.plan[inside]
        local = box.to_local(pts[-1])
        steps = []
        for k, sign in itertools.product(range(3), (-1.0, 1.0)):
            q = local.copy()
            q[k] = sign * box.half[k]
            steps.append((abs(q[k] - local[k]), box.to_world(q)))
        for _, q in sorted(steps, key=lambda s: s[0]):
            if not router.below_floor(q[None]) and not any(o.hits_segment(pts[-1], q) for o in solids):
                pts.append(q)
                break
        else:
            raise NoPathError(f"{label} is boxed in by overlapping obstacles {box.name!r}: every step out of "
                              "their enclosing box runs into one of them")
    raise NoPathError(f"{label} is boxed in by overlapping obstacles near it")


def plan_path(
    start: np.ndarray,
    goal: np.ndarray,
    obstacles: list[Solid],
    margin: float = 0.0,
    clearance: float = 0.005,
    floor: tuple[np.ndarray, float] | None = None,
) -> AvoidResult:
    """Collision-free polyline from ``start`` to ``goal`` around ``obstacles``.

    ``margin`` inflates every obstacle (gripper size); ``clearance`` (m) is the extra gap
    the faces are planned at, so the path never grazes an inflated obstacle. ``floor``,
    a unit normal n and offset c, keeps every path point in the half-space n·p ≥ c (so
    an obstacle standing on the floor is never passed underneath).
    Raises :class:`NoPathError` when start or goal lies inside an inflated obstacle or no
    path is found.
    """
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if floor is not None:
        floor = (np.asarray(floor[0], dtype=float), float(floor[1]))
        for label, p in (("start", start), ("goal", goal)):
            if p @ floor[0] < floor[1]:
                raise NoPathError(f"{label} {np.round(p, 4).tolist()} lies below the floor", end=label)
    check = [o.inflated(margin) for o in obstacles]
    for label, p in (("start", start), ("goal", goal)):
        for o in check:
            if o.contains(p):
                raise NoPathError(
                    f"{label} {np.round(p, 4).tolist()} lies inside obstacle {o.name!r} (margin {margin} m)",
                    end=label, obstacle=o.name,
                )
    boxes = [o.inflated(margin + clearance).bounding_box() for o in obstacles]
    merges = 0
    while True:
        router = _Router(boxes, clearance, floor)
        try:
            head = _escape(start, router, check, "start")
            tail = _escape(goal, router, check, "goal")[::-1]
            middle = router.route(head[-1], tail[0], 0)
            path = np.array(head[:-1] + middle + tail[1:])
            break
        except _BlockedError as err:
            i = err.index
            group = [j for j in range(len(boxes)) if j != i and _boxes_overlap(boxes[i], boxes[j])]
            if not group:
                raise NoPathError(
                    f"no path around obstacle {boxes[i].name!r}: its face detours are blocked "
                    "and it overlaps nothing to merge with"
                ) from None
            members = [boxes[i]] + [boxes[j] for j in group]
            merged = _enclosing(members, boxes[i], "+".join(b.name for b in members))
            boxes = [b for j, b in enumerate(boxes) if j != i and j not in group] + [merged]
            merges += 1
    if floor is not None and np.any(path @ floor[0] < floor[1] - 1e-9):
        raise NoPathError("internal check: planned path dips under the floor; refusing to return it")
    for o in check:
        if path_hits(path, o):
            raise NoPathError(f"internal check: planned path touches obstacle {o.name!r}; refusing to return it")
    return AvoidResult(path=path, merges=merges, boxes=boxes)
