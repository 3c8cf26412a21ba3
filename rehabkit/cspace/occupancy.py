"""The Cartesian occupancy grid Ψ of a scene's obstacles (after Carbone et al., eq. 1).

Ψ_ijk = 1 when the cell's centre lies inside an obstacle grown by ``inflate``
(the radius of the robot's thin links, whose axes are what is tested), else 0.
Points outside the grid are free. Coordinates are in the robot base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from rehabkit.core.scenario.models import WorldObject
from rehabkit.cspace.cache import cached_array, key_of
from rehabkit.models.chain import inv_se3, rpy_to_matrix


@dataclass
class OccupancyGrid:
    """Ψ, and the metric distance from a cell to the nearest occupied one where asked."""

    origin: np.ndarray  # centre of cell (0, 0, 0)
    resolution: float
    occupied: np.ndarray  # bool (nx, ny, nz)

    @cached_property
    def _occupied_cells(self):
        from scipy.spatial import cKDTree  # only where clearances are asked for

        return cKDTree(np.argwhere(self.occupied).astype(float)) if self.occupied.any() else None

    def _index(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.floor((points - self.origin) / self.resolution + 0.5).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.occupied.shape)), axis=-1)
        return np.clip(idx, 0, np.array(self.occupied.shape) - 1), inside

    def hits(self, points: np.ndarray) -> np.ndarray:
        """Whether each point (..., 3) is in an occupied cell."""
        idx, inside = self._index(points)
        return inside & self.occupied[idx[..., 0], idx[..., 1], idx[..., 2]]

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance [m] from each point (..., 3) to the nearest occupied cell (inf off the grid, 0 inside).

        Measured between cell centres, as a Euclidean distance transform of the grid gives it, but only for the
        cells asked about (a transform of a fine grid costs ~0.5 s; Ψ is mostly empty)."""
        idx, inside = self._index(points)
        if self._occupied_cells is None:
            return np.full(inside.shape, np.inf)
        d = self._occupied_cells.query(idx.reshape(-1, 3).astype(float))[0].reshape(inside.shape) * self.resolution
        return np.where(inside, d, np.inf)


def _inside(obj: WorldObject, local: np.ndarray, grow: float) -> np.ndarray:
    if obj.shape == "box":
        return np.all(np.abs(local) <= np.asarray(obj.size) + grow, axis=-1)
    if obj.shape == "sphere":
        return np.linalg.norm(local, axis=-1) <= obj.size[0] + grow
    radius, half = obj.size
    return (np.hypot(local[..., 0], local[..., 1]) <= radius + grow) & (np.abs(local[..., 2]) <= half + grow)


def rasterise(objects: list[WorldObject], base_pose: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              resolution: float = 0.005, inflate: float = 0.0) -> OccupancyGrid:
    """Ψ over the box [lower, upper] (robot base frame) for the static obstacles among ``objects``."""
    origin = np.asarray(lower, float)
    shape = tuple(int(n) for n in np.ceil((np.asarray(upper) - origin) / resolution).astype(int) + 1)
    static = [obj for obj in objects if not (obj.dynamic or obj.mocap)]  # moving ones are not in the static map

    def build() -> np.ndarray:
        centres = origin + np.indices(shape).reshape(3, -1).T * resolution
        to_base = inv_se3(base_pose)
        occupied = np.zeros(len(centres), bool)
        for obj in static:
            pose = np.eye(4)
            pose[:3, :3] = rpy_to_matrix(np.radians(obj.pose.rpy_deg))
            pose[:3, 3] = obj.pose.position
            in_obj = inv_se3(to_base @ pose)  # base frame → object frame
            local = centres @ in_obj[:3, :3].T + in_obj[:3, 3]
            occupied |= _inside(obj, local, inflate)
        return occupied.reshape(shape)

    key = key_of("psi-v1", [o.model_dump(mode="json") for o in static], np.asarray(base_pose, float), origin,
                 shape, float(resolution), float(inflate))
    return OccupancyGrid(origin, resolution, cached_array("psi", key, build))
