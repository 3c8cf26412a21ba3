"""Random points of a workspace table, for reaching studies (seeded: the same draws every time)."""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.interfaces import PlanningError
from rehabkit.workspace.grid import VoxelWorkspace

MAX_DRAWS = 10_000


def random_inner(ws: VoxelWorkspace, rng: np.random.Generator) -> np.ndarray:
    """The centre of a uniformly drawn inner voxel."""
    inner = ws.inner_points()
    return inner[rng.integers(len(inner))]


def random_inner_not_straight(ws: VoxelWorkspace, rng: np.random.Generator, start: np.ndarray) -> np.ndarray:
    """An inner voxel centre that the straight segment from ``start`` cannot reach inside the workspace."""
    inner = ws.inner_points()
    for _ in range(MAX_DRAWS):
        point = inner[rng.integers(len(inner))]
        if not ws.segment_inner(start, point):
            return point
    raise PlanningError(f"no point in {MAX_DRAWS} draws that a straight line from {np.round(start, 3)} cannot reach")
