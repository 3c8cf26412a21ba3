"""Box, cylinder and sphere obstacles with exact segment-versus-solid tests.

Every solid is closed: a segment touching the surface intersects it. Tests are exact
up to floating-point round-off (no sampling along the segment).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _rotation(axes: np.ndarray | None) -> np.ndarray:
    if axes is None:
        return np.eye(3)
    rot = np.asarray(axes, dtype=float).reshape(3, 3)
    if float(np.abs(rot.T @ rot - np.eye(3)).max()) > 1e-9:
        raise ValueError("obstacle axes must form an orthonormal rotation matrix (columns = box axes)")
    return rot


@dataclass(frozen=True)
class Box:
    """Oriented box: centre, rotation whose columns are the box axes, half extents along them."""

    center: np.ndarray
    half: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = "box"

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", np.asarray(self.center, dtype=float).reshape(3))
        object.__setattr__(self, "half", np.asarray(self.half, dtype=float).reshape(3))
        object.__setattr__(self, "rotation", _rotation(self.rotation))
        if self.half.min() <= 0:
            raise ValueError(f"box {self.name!r}: half extents must be positive, got {self.half.tolist()}")

    def to_local(self, p: np.ndarray) -> np.ndarray:
        return (np.asarray(p, dtype=float) - self.center) @ self.rotation

    def to_world(self, p: np.ndarray) -> np.ndarray:
        return np.asarray(p, dtype=float) @ self.rotation.T + self.center

    def inflated(self, margin: float) -> Box:
        return Box(self.center, self.half + margin, self.rotation, self.name)

    def bounding_box(self) -> Box:
        return self

    def contains(self, p: np.ndarray) -> bool:
        return bool(np.all(np.abs(self.to_local(p)) <= self.half))

    def corners(self) -> np.ndarray:
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
        return self.to_world(signs * self.half)

    def distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance of points (N, 3) to the box surface (negative inside)."""
        d = np.abs(self.to_local(np.atleast_2d(pts))) - self.half
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
        return np.where(outside > 0, outside, d.max(axis=1))

    def segment_interval(self, p0: np.ndarray, p1: np.ndarray) -> tuple[float, float] | None:
        """Parameter interval [t_in, t_out] ⊂ [0, 1] of the segment inside the box, or None."""
        return _slab_interval(self.to_local(p0), self.to_local(p1), self.half)

    def hits_segment(self, p0: np.ndarray, p1: np.ndarray) -> bool:
        return self.segment_interval(p0, p1) is not None


def _slab_interval(a: np.ndarray, b: np.ndarray, half: np.ndarray) -> tuple[float, float] | None:
    d = b - a
    t0, t1 = 0.0, 1.0
    for k in range(3):
        if abs(d[k]) < 1e-15:
            if abs(a[k]) > half[k]:
                return None
            continue
        ta, tb = (-half[k] - a[k]) / d[k], (half[k] - a[k]) / d[k]
        if ta > tb:
            ta, tb = tb, ta
        t0, t1 = max(t0, ta), min(t1, tb)
        if t0 > t1:
            return None
    return t0, t1


@dataclass(frozen=True)
class Sphere:
    center: np.ndarray
    radius: float
    name: str = "sphere"

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", np.asarray(self.center, dtype=float).reshape(3))
        if self.radius <= 0:
            raise ValueError(f"sphere {self.name!r}: radius must be positive")

    def inflated(self, margin: float) -> Sphere:
        return Sphere(self.center, self.radius + margin, self.name)

    def bounding_box(self) -> Box:
        return Box(self.center, np.full(3, self.radius), np.eye(3), self.name)

    def contains(self, p: np.ndarray) -> bool:
        return float(np.linalg.norm(np.asarray(p) - self.center)) <= self.radius

    def distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance of points (N, 3) to the sphere surface (negative inside)."""
        return np.linalg.norm(np.atleast_2d(pts) - self.center, axis=1) - self.radius

    def hits_segment(self, p0: np.ndarray, p1: np.ndarray) -> bool:
        p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
        d = p1 - p0
        dd = float(d @ d)
        t = 0.0 if dd == 0 else float(np.clip((self.center - p0) @ d / dd, 0.0, 1.0))
        return float(np.linalg.norm(p0 + t * d - self.center)) <= self.radius


@dataclass(frozen=True)
class Cylinder:
    """Solid cylinder: centre, unit axis, radius, half length along the axis."""

    center: np.ndarray
    axis: np.ndarray
    radius: float
    half_length: float
    name: str = "cylinder"

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", np.asarray(self.center, dtype=float).reshape(3))
        axis = np.asarray(self.axis, dtype=float).reshape(3)
        object.__setattr__(self, "axis", axis / np.linalg.norm(axis))
        if self.radius <= 0 or self.half_length <= 0:
            raise ValueError(f"cylinder {self.name!r}: radius and half length must be positive")

    def _frame(self) -> np.ndarray:
        z = self.axis
        helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        return np.column_stack([x, np.cross(z, x), z])

    def inflated(self, margin: float) -> Cylinder:
        return Cylinder(self.center, self.axis, self.radius + margin, self.half_length + margin, self.name)

    def bounding_box(self) -> Box:
        return Box(self.center, np.array([self.radius, self.radius, self.half_length]), self._frame(), self.name)

    def contains(self, p: np.ndarray) -> bool:
        v = np.asarray(p, dtype=float) - self.center
        h = float(v @ self.axis)
        return abs(h) <= self.half_length and float(np.linalg.norm(v - h * self.axis)) <= self.radius

    def distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance of points (N, 3) to the cylinder surface (negative inside)."""
        v = np.atleast_2d(pts) - self.center
        h = v @ self.axis
        d = np.column_stack([np.linalg.norm(v - h[:, None] * self.axis, axis=1) - self.radius,
                             np.abs(h) - self.half_length])
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
        return np.where(outside > 0, outside, d.max(axis=1))

    def hits_segment(self, p0: np.ndarray, p1: np.ndarray) -> bool:
        a = np.asarray(p0, dtype=float) - self.center
        d = np.asarray(p1, dtype=float) - np.asarray(p0, dtype=float)
        ha, hd = float(a @ self.axis), float(d @ self.axis)
        # axial slab
        if abs(hd) < 1e-15:
            if abs(ha) > self.half_length:
                return False
            t0, t1 = 0.0, 1.0
        else:
            ta, tb = sorted(((-self.half_length - ha) / hd, (self.half_length - ha) / hd))
            t0, t1 = max(0.0, ta), min(1.0, tb)
            if t0 > t1:
                return False
        # radial: |a_perp + t d_perp|^2 <= r^2 somewhere in [t0, t1]; convex quadratic in t
        ap, dp = a - ha * self.axis, d - hd * self.axis
        qa, qb = float(dp @ dp), float(ap @ dp)
        t = t0 if qa == 0 else float(np.clip(-qb / qa, t0, t1))
        return float(np.linalg.norm(ap + t * dp)) <= self.radius


Solid = Box | Sphere | Cylinder


def make_solid(shape: str, size: tuple[float, ...], center: np.ndarray, rotation: np.ndarray, name: str) -> Solid:
    """A solid from a scene primitive (MuJoCo sizes: box half extents, cylinder radius and
    half length along its local z, sphere radius)."""
    if shape == "box":
        return Box(center, np.asarray(size, float), rotation, name)
    if shape == "cylinder":
        return Cylinder(center, np.asarray(rotation)[:, 2], size[0], size[1], name)
    if shape == "sphere":
        return Sphere(center, size[0], name)
    raise ValueError(f"no solid for shape {shape!r}; box, cylinder and sphere are known")


def path_hits(path: np.ndarray, solid: Solid) -> bool:
    """Whether any segment of a polyline (N×3) intersects the closed solid."""
    pts = np.asarray(path, dtype=float)
    return any(solid.hits_segment(pts[i], pts[i + 1]) for i in range(len(pts) - 1))
