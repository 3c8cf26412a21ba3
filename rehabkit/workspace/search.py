"""Paths over the inner voxels of a workspace (26-connected graph).

Four searches, as compared by Loconsole et al.:

* ``astar``: optimal A* with h(x) = ||x - x_g||;
* ``astar`` with ``weight=1.5``: suboptimal, faster (h amplified);
* ``hill``: greedy, always steps to the unvisited neighbour nearest the goal;
* ``beam``: greedy, steps to the neighbour nearest the point ``k`` ahead of the
  current node on the line to the goal, so it keeps to that line.

The greedy ones can get stuck (a dead end, or wandering past a step budget):
they raise :class:`SearchFailedError` instead of looping. No search ever leaves the
inner voxels. Paths are voxel-centre polylines from start to goal, both
included (start and goal must be inner).
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from rehabkit.workspace.grid import INNER, NEIGHBOURS, VoxelWorkspace


class SearchFailedError(RuntimeError):
    """A search found no path; the message says why, ``kind`` which way: ``"not-inner"`` (an end outside the inner
    workspace), ``"apart"`` (the ends in separate parts of it), ``"no-arrival"`` (a greedy search out of steps) or
    ``"stuck"`` (a greedy search at a dead end)."""

    def __init__(self, message: str, kind: str):
        super().__init__(message)
        self.kind = kind




def _setup(ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray) -> tuple[int, int, np.ndarray, list[int]]:
    labels = ws.labels
    s, g = ws.index(np.vstack([start, goal]))
    for name, i in (("start", s), ("goal", g)):
        if np.any(i < 0) or np.any(i >= labels.shape) or labels[tuple(i)] != INNER:
            raise SearchFailedError(f"{name} {np.round(ws.centre(i), 3).tolist()} is not an inner voxel", "not-inner")
    ny, nz = labels.shape[1], labels.shape[2]
    offsets = [int(dx * ny * nz + dy * nz + dz) for dx, dy, dz in NEIGHBOURS]
    flat_s = int(np.ravel_multi_index(s, labels.shape))
    flat_g = int(np.ravel_multi_index(g, labels.shape))
    return flat_s, flat_g, labels.reshape(-1), offsets


def _coords(ws: VoxelWorkspace, flat: list[int]) -> np.ndarray:
    return ws.centre(np.column_stack(np.unravel_index(np.asarray(flat), ws.shape)))


def astar(ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray, weight: float = 1.0) -> np.ndarray:
    """Shortest (``weight`` = 1) or weighted-A* path of voxel centres [m]."""
    s, g, labels, offsets = _setup(ws, start, goal)
    shape = ws.shape
    nz, nyz = shape[2], shape[1] * shape[2]
    gx, gy, gz = g // nyz, (g // nz) % shape[1], g % nz
    steps = [math.sqrt(dx * dx + dy * dy + dz * dz) for dx, dy, dz in NEIGHBOURS]
    moves = list(zip(offsets, steps))
    cost = {s: 0.0}
    parent = {s: -1}
    heap = [(0.0, s)]
    closed = set()
    while heap:
        _, node = heapq.heappop(heap)
        if node == g:
            break
        if node in closed:
            continue
        closed.add(node)
        base = cost[node]
        for off, step in moves:
            nb = node + off
            if labels[nb] != INNER or nb in closed:
                continue
            c = base + step
            if c < cost.get(nb, math.inf):
                cost[nb] = c
                parent[nb] = node
                x, y, z = nb // nyz, (nb // nz) % shape[1], nb % nz
                h = math.sqrt((x - gx) ** 2 + (y - gy) ** 2 + (z - gz) ** 2)
                heapq.heappush(heap, (c + weight * h, nb))
    else:
        raise SearchFailedError("start and goal are in separate parts of the inner workspace", "apart")
    path = [g]
    while parent[path[-1]] != -1:
        path.append(parent[path[-1]])
    return _coords(ws, path[::-1])


def _greedy(ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray, cost, name: str,
            max_steps: int | None) -> np.ndarray:
    s, g, labels, offsets = _setup(ws, start, goal)
    coords = lambda flat: ws.centre(np.array(np.unravel_index(flat, ws.shape)))  # noqa: E731
    goal_xyz = coords(g)
    budget = max_steps or int(4 * np.linalg.norm(coords(s) - goal_xyz) / ws.resolution) + 50
    path, visited, node = [s], {s}, s
    while node != g:
        if len(path) > budget:
            raise SearchFailedError(f"{name}: no arrival after {budget} steps (wandering in a concavity)",
                                    "no-arrival")
        candidates = [node + off for off in offsets]
        free = [c for c in candidates if labels[c] == INNER and c not in visited]
        if not free:
            raise SearchFailedError(f"{name}: stuck at {np.round(coords(node), 3).tolist()} (every neighbour "
                                    "visited or outside the inner workspace)", "stuck")
        here = coords(node)
        pts = ws.centre(np.column_stack(np.unravel_index(np.asarray(free), ws.shape)))
        node = free[int(np.argmin(cost(here, pts, goal_xyz)))]
        visited.add(node)
        path.append(node)
    return _coords(ws, path)


def hill(ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray, max_steps: int | None = None) -> np.ndarray:
    """Greedy hill climbing: f(x) = ||x - x_g||."""
    return _greedy(ws, start, goal, lambda here, pts, xg: np.linalg.norm(pts - xg, axis=1), "hill", max_steps)


def beam(ws: VoxelWorkspace, start: np.ndarray, goal: np.ndarray, k: float = 0.05,
         max_steps: int | None = None) -> np.ndarray:
    """Greedy beam: f(x) = ||x_c + k (x_g - x_c)/||x_g - x_c|| - x||, ``k`` [m] (capped at the goal)."""

    def cost(here, pts, xg):
        d = xg - here
        dist = np.linalg.norm(d)
        aim = here + min(k, dist) * d / dist
        return np.linalg.norm(pts - aim, axis=1)

    return _greedy(ws, start, goal, cost, "beam", max_steps)


def decimate(path: np.ndarray, n: int) -> np.ndarray:
    """Every ``n``-th point of a path, always keeping both ends."""
    if n <= 1 or len(path) <= 2:
        return path
    keep = list(range(0, len(path) - 1, n)) + [len(path) - 1]
    return path[keep]


def path_length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0
