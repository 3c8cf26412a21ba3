"""The joint matrix Θ (after Carbone et al., eq. 2) and the clearance ρ of every configuration.

Θ marks each configuration of an ε-grid of joint space collision-free when
none of the robot's cluster points falls in an occupied cell of Ψ. ρ is each
configuration's joint-space distance to the nearest colliding one (a distance
transform of Θ, in radians). Queries between grid nodes use the nearest node.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from rehabkit.cspace.cache import cached_array, key_of
from rehabkit.cspace.occupancy import OccupancyGrid


@dataclass
class JointMatrix:
    """Θ and ρ on a regular grid of joint values."""

    lower: np.ndarray
    step: float  # ε [rad]
    free: np.ndarray  # bool, one axis per joint

    def __post_init__(self) -> None:
        self.rho = ndimage.distance_transform_edt(self.free) * self.step  # 0 where colliding

    @property
    def upper(self) -> np.ndarray:
        return self.lower + (np.array(self.free.shape) - 1) * self.step

    def _index(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.rint((np.asarray(q, float) - self.lower) / self.step).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.free.shape)), axis=-1)
        return np.clip(idx, 0, np.array(self.free.shape) - 1), inside

    def is_free(self, q: np.ndarray) -> np.ndarray:
        idx, inside = self._index(q)
        return inside & self.free[tuple(np.moveaxis(idx, -1, 0))]

    def clearance(self, q: np.ndarray) -> np.ndarray:
        idx, inside = self._index(q)
        return np.where(inside, self.rho[tuple(np.moveaxis(idx, -1, 0))], 0.0)


def build_joint_matrix(points: Callable[[np.ndarray], np.ndarray], psi: OccupancyGrid, lower: np.ndarray,
                       upper: np.ndarray, step: float, chunk: int = 4096) -> JointMatrix:
    """Θ for cluster points ``points(q (N, n)) -> (N, P, 3)`` (robot base frame) against Ψ."""
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(lower, upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))

    def build() -> np.ndarray:
        free = np.empty(len(grid), bool)
        for i in range(0, len(grid), chunk):
            free[i : i + chunk] = ~psi.hits(points(grid[i : i + chunk])).any(axis=1)
        return free.reshape([len(a) for a in axes])

    # the robot enters the key as its cluster points at a spread of configurations: other geometry, other Θ
    probe = grid[:: max(1, len(grid) // 64)]
    key = key_of("theta-v1", psi.occupied, psi.origin, float(psi.resolution), np.asarray(lower, float),
                 np.asarray(upper, float), float(step), points(probe))
    return JointMatrix(np.asarray(lower, float), step, cached_array("theta", key, build))
