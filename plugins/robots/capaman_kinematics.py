"""Kinematics of the Cassino Parallel Manipulator (CaPaMan).

Three legs at 0°, 120°, 240° around the fixed plate. Leg k is a planar
articulated parallelogram standing in the vertical plane tangent to the
circle of radius ``r_base``: frame link a on the base (centred at O_k), crank
b at input angle α_k (measured from the tangent t_k toward the vertical),
coupler c = a kept parallel to the frame link, follower d = b. A bar h rises
from the middle of the coupler; at its top a prismatic joint slides along the
radial direction e_k (normal to the leg plane) and carries the spherical joint
H_k of the movable plate, at radius ``r_plate`` in the plate's frame.

So each leg fixes two coordinates of H_k in its plane:
    (H_k − O_k)·t_k = b cos α_k,    (H_k − O_k)·z − h = b sin α_k
and leaves the radial one free — six equations for the plate's six pose
coordinates, hence a 3-DoF plate for three cranks.

Published CaPaMan dimensions could not be read; a = c = 200 mm, b = d = 80 mm,
h = 100 mm and plate radii of 110 mm are the commonly cited values and are
used here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LEG_ANGLES = np.radians([0.0, 120.0, 240.0])


@dataclass(frozen=True)
class CapamanGeometry:
    """Dimensions [m]."""

    a: float = 0.200  # frame link and coupler
    b: float = 0.080  # crank and follower
    h: float = 0.100  # bar on the coupler
    r_base: float = 0.110  # leg planes' distance from the fixed plate's centre
    r_plate: float = 0.110  # spherical joints' radius on the movable plate
    base_height: float = 0.020  # crank pivots above the base frame (fixed plate thickness)

    @property
    def radial(self) -> np.ndarray:
        """e_k, (3, 3): rows are the legs' radial directions (normals of their planes)."""
        return np.column_stack([np.cos(LEG_ANGLES), np.sin(LEG_ANGLES), np.zeros(3)])

    @property
    def tangent(self) -> np.ndarray:
        """t_k, (3, 3): in-plane horizontal directions; α is measured from t_k toward z."""
        return np.column_stack([-np.sin(LEG_ANGLES), np.cos(LEG_ANGLES), np.zeros(3)])

    @property
    def centres(self) -> np.ndarray:
        """O_k, (3, 3): middles of the frame links."""
        return self.r_base * self.radial + np.array([0.0, 0.0, self.base_height])

    @property
    def plate_points(self) -> np.ndarray:
        """H_k in the movable plate's frame, (3, 3)."""
        return self.r_plate * self.radial

    def home(self) -> tuple[np.ndarray, np.ndarray]:
        """Plate pose (position, rotation) with every crank at 90°."""
        return np.array([0.0, 0.0, self.base_height + self.b + self.h]), np.eye(3)


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors → (..., 3, 3) cross-product matrices."""
    v = np.asarray(v, float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def expmap(phi: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from rotation vectors (..., 3) (Rodrigues)."""
    phi = np.asarray(phi, float)
    angle = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = skew(phi)
    small = angle < 1e-12
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 1.0, np.sin(safe) / safe)
    c = np.where(small, 0.5, (1 - np.cos(safe)) / safe**2)
    return np.eye(3) + s * K + c * (K @ K)


def plate_joints(geo: CapamanGeometry, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """World positions (..., 3 legs, 3) of the spherical joints H_k for plate poses."""
    return p[..., None, :] + np.einsum("...ij,kj->...ki", R, geo.plate_points)


def inverse(geo: CapamanGeometry, p: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crank angles for plate poses, closed form.

    Returns:
        α (..., 3) [rad]; the slider travels s_k (..., 3) [m]; and each leg's
        residual |(u, w)| − b [m], zero when the pose is one the mechanism can take.
    """
    rel = plate_joints(geo, p, R) - geo.centres
    u = np.einsum("...ki,ki->...k", rel, geo.tangent)
    w = rel[..., 2] - geo.h
    alpha = np.arctan2(w, u)
    slide = np.einsum("...ki,ki->...k", rel, geo.radial)
    return alpha, slide, np.hypot(u, w) - geo.b


def forward(geo: CapamanGeometry, alpha: np.ndarray, p0: np.ndarray | None = None, R0: np.ndarray | None = None,
            iterations: int = 30, tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plate poses for crank angles (..., 3), by Newton's method on the six leg equations, batched.

    Starts from the home pose (or p0, R0) and updates the rotation on the left,
    R ← exp(δφ) R. The Jacobian is analytic: a residual along direction d at
    joint H = p + R c has ∂/∂p = d and ∂/∂δφ = (R c) × d.

    Returns:
        positions (..., 3), rotations (..., 3, 3), and the largest residual of each [m].
    """
    alpha = np.atleast_2d(np.asarray(alpha, float))
    n = alpha.shape[0]
    hp, hR = geo.home()
    p = np.tile(hp if p0 is None else p0, (n, 1)).astype(float)
    R = np.tile(hR if R0 is None else R0, (n, 1, 1)).astype(float)
    t, z = geo.tangent, np.array([0.0, 0.0, 1.0])
    target = np.concatenate([geo.b * np.cos(alpha), geo.h + geo.b * np.sin(alpha)], axis=1)  # (n, 6)
    dirs = np.concatenate([t, np.tile(z, (3, 1))])  # (6, 3)
    for _ in range(iterations):
        rc = np.einsum("nij,kj->nki", R, geo.plate_points)  # R c_k
        rel = p[:, None, :] + rc - geo.centres  # H_k − O_k
        rel6 = np.concatenate([rel, rel], axis=1)
        residual = np.einsum("nki,ki->nk", rel6, dirs) - target
        if np.abs(residual).max() < tol:
            break
        J = np.zeros((n, 6, 6))
        J[:, :, :3] = dirs
        J[:, :, 3:] = np.cross(np.concatenate([rc, rc], axis=1), dirs)
        step = np.linalg.solve(J, -residual[..., None])[..., 0]
        p = p + step[:, :3]
        R = expmap(step[:, 3:]) @ R
    return p, R, np.abs(residual).max(axis=1)


def forward_jacobian(geo: CapamanGeometry, alpha: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """∂(p, φ)/∂α (6, 3) at a solved pose: the plate's position and its rotation (a left increment, as
    :func:`forward` applies) per unit of each crank angle, by implicit differentiation of the leg equations."""
    rc = R @ geo.plate_points.T  # (3, legs): R c_k
    dirs = np.concatenate([geo.tangent, np.tile([0.0, 0.0, 1.0], (3, 1))])
    J = np.zeros((6, 6))
    J[:, :3] = dirs
    J[:, 3:] = np.cross(np.concatenate([rc.T, rc.T]), dirs)
    alpha = np.asarray(alpha, float)
    d_target = np.zeros((6, 3))  # ∂target/∂α: −b sin α_k in leg k's tangent row, b cos α_k in its vertical row
    d_target[np.arange(3), np.arange(3)] = -geo.b * np.sin(alpha)
    d_target[3 + np.arange(3), np.arange(3)] = geo.b * np.cos(alpha)
    return np.linalg.solve(J, d_target)
