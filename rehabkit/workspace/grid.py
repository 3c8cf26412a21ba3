"""A voxel look-up table of a robot's reachable workspace, and its queries.

Labels per voxel: 0 unreachable, 1 boundary (reachable, with an unreachable
neighbour among its 26), 2 inner. Planning uses inner voxels only, so paths keep
one voxel of margin from the workspace surface (where the arm nears its joint
limits or a singularity). Points are in the robot base frame [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

UNREACHABLE, BOUNDARY, INNER = 0, 1, 2

# the 26 neighbours of a voxel and the length of each step in voxels
NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)])
STEP_LENGTHS = np.linalg.norm(NEIGHBOURS, axis=1)


@lru_cache(maxsize=512)
def _unit_steps(n: int) -> np.ndarray:
    return np.linspace(0.0, 1.0, n)[:, None]


@dataclass
class VoxelWorkspace:
    """Labels on a regular grid.

    Attributes:
        origin: Centre of voxel (0, 0, 0) [m].
        resolution: Voxel edge [m].
        labels: (nx, ny, nz) uint8 labels.
        queries: Look-ups made so far (a counter, for reporting).
    """

    origin: np.ndarray
    resolution: float
    labels: np.ndarray
    queries: int = field(default=0, repr=False)
    _fast: tuple | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        lab = self.labels
        border = [lab[0], lab[-1], lab[:, 0], lab[:, -1], lab[:, :, 0], lab[:, :, -1]]
        if any((face == INNER).any() for face in border):
            raise ValueError("a workspace table's outer layer of voxels must not be inner")

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.labels.shape

    @property
    def nbytes(self) -> int:
        return int(self.labels.nbytes)

    def index(self, points: np.ndarray) -> np.ndarray:
        """Integer voxel indices (N, 3) of points (N, 3); may lie outside the grid."""
        return np.floor((np.asarray(points, dtype=float) - self.origin) / self.resolution + 0.5).astype(np.int64)

    def centre(self, idx: np.ndarray) -> np.ndarray:
        """Centres [m] of voxels with indices ``idx``."""
        return self.origin + np.asarray(idx, dtype=float) * self.resolution

    def label(self, points: np.ndarray) -> np.ndarray:
        """Labels of the voxels containing ``points``; points outside the grid are unreachable."""
        pts = np.atleast_2d(points)
        idx = self.index(pts)
        inside = np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)
        out = np.zeros(len(pts), dtype=np.uint8)
        i = idx[inside]
        out[inside] = self.labels[i[:, 0], i[:, 1], i[:, 2]]
        self.queries += 1
        return out

    def reachable(self, point: np.ndarray) -> bool:
        return bool(self.label(point)[0] >= BOUNDARY)

    def inner(self, point: np.ndarray) -> bool:
        return bool(self.label(point)[0] == INNER)

    def segment_inner(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether the straight segment a→b stays in the reachable workspace, by the table alone.

        Samples one voxel apart, each required to fall in an inner voxel, are
        enough: a point between two samples is within half a voxel of one, so it
        lies in that inner voxel or one of its 26 neighbours — all reachable by
        the definition of inner.
        """
        fast = self._fast
        if fast is None or fast[0] is not self.labels:
            ny, nz = self.labels.shape[1:]
            strides = np.array([ny * nz, nz, 1], dtype=np.intp)
            last = np.array(self.labels.shape, dtype=np.intp) - 1
            fast = (self.labels, (self.labels == INNER).reshape(-1), strides, last, self.origin - 0.5 * self.resolution)
            self._fast = fast
        _, is_inner, strides, last, corner = fast
        # continuous voxel coordinates, whose floor is the index
        ia = (a - corner) / self.resolution
        d = (b - corner) / self.resolution - ia
        idx = (ia + _unit_steps(int(math.sqrt(d @ d)) + 2) * d).astype(np.intp)
        # samples off the grid land on its border, which is never inner: no separate bounds test
        np.clip(idx, 0, last, out=idx)
        self.queries += 1
        return bool(is_inner.take(idx @ strides).all())

    def proxy_point(self, start: np.ndarray, target: np.ndarray, level: int = INNER) -> tuple[np.ndarray, int]:
        """The point nearest ``target`` on start→target that is reachable, by bisection.

        ``start`` must be reachable. One look-up decides whether a proxy is
        needed at all; bisection then stops when the bracket is shorter than a
        voxel, so a segment of length L needs ceil(log2(L / resolution)) more
        (7 up to 1.28 m at 1 cm).

        Returns:
            The proxy point (``target`` itself when reachable) and the bisection look-ups used.
        """
        start, target = np.asarray(start, float), np.asarray(target, float)
        used = 0
        if self.label(target)[0] >= level:
            return target, used
        lo, hi = 0.0, 1.0  # lo: known reachable fraction, hi: known unreachable
        length = np.linalg.norm(target - start)
        while (hi - lo) * length > self.resolution:
            mid = 0.5 * (lo + hi)
            used += 1
            if self.label(start + mid * (target - start))[0] >= level:
                lo = mid
            else:
                hi = mid
        return start + lo * (target - start), used

    def inner_points(self) -> np.ndarray:
        """Centres of all inner voxels (N, 3)."""
        return self.centre(np.argwhere(self.labels == INNER))

    def boundary_points(self) -> np.ndarray:
        """Centres of all boundary voxels (N, 3), e.g. to draw the workspace."""
        return self.centre(np.argwhere(self.labels == BOUNDARY))
