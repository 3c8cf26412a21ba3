"""Acceleration and angular velocity of a rigid body from triaxial accelerometers.

An accelerometer at r (body frame) with sensing axes s reads
s·(a_B + α × r + ω × (ω × r)) + a₀. Stacking the axes of several sensors gives
y = M z + a₀ with z = [a_B, α, ω_x², ω_y², ω_z², ω_xω_y, ω_yω_z, ω_xω_z], linear
in z. Four sensors (12 axes) determine z when they are *not coplanar*: with
all of them in one plane, α and the ω products share their coefficients and M
has rank 9. z is solved by least squares; ω comes from the products, its
overall sign (which they cannot tell) from continuity with the previous
estimate advanced by α dt.
"""

from __future__ import annotations

import numpy as np

from rehabkit.estimation.recursions import array_sample, ekf_omega, omega_from_products


def design_row(axis: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Coefficients of z in one axis reading."""
    s = np.asarray(axis, float)
    r = np.asarray(r, float)
    sr = s @ r
    quad = [s[0] * r[0] - sr, s[1] * r[1] - sr, s[2] * r[2] - sr,
            s[0] * r[1] + s[1] * r[0], s[1] * r[2] + s[2] * r[1], s[0] * r[2] + s[2] * r[0]]
    return np.concatenate([s, np.cross(r, s), quad])  # s·(α × r) = α·(r × s)


class AccelerometerArray:
    """A rigid set of triaxial accelerometers (positions and axes in the body frame)."""

    def __init__(self, positions: np.ndarray, axes: np.ndarray | None = None):
        self.positions = np.asarray(positions, float).reshape(-1, 3)
        n = len(self.positions)
        self.axes = np.tile(np.eye(3), (n, 1, 1)) if axes is None else np.asarray(axes, float).reshape(n, 3, 3)
        self.M = np.array([design_row(self.axes[i, k], self.positions[i]) for i in range(n) for k in range(3)])
        rank = np.linalg.matrix_rank(self.M)
        if rank < 12:
            raise ValueError(f"these {n} accelerometers determine only {rank} of the 12 motion terms; "
                             "mount at least four, not all in one plane")
        self.M_pinv = np.linalg.pinv(self.M)
        self._omega, self._omega_known = np.zeros(3), False  # the last ω from the products: their sign's reference

    def solve(self, readings: np.ndarray, offsets: np.ndarray | float = 0.0) -> np.ndarray:
        """z (12,) from the stacked readings (n*3,) minus the calibrated offsets."""
        return self.M_pinv @ (np.asarray(readings, float).ravel() - np.asarray(offsets, float).ravel())

    def omega(self, z: np.ndarray, dt: float) -> np.ndarray:
        """Angular velocity from z's quadratic terms, its sign kept continuous over calls."""
        w = omega_from_products(np.ascontiguousarray(z, dtype=float), dt, self._omega, self._omega_known)
        self._omega_known = True
        return w

    def sample(self, raw: np.ndarray, filtered: np.ndarray, variances: np.ndarray, offsets: np.ndarray,
               ekf: AngularVelocityEKF, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One online sample in one compiled call, for a sensor read at the control rate: z from the raw and from
        the filtered readings (n, 3) — :meth:`solve` — and ω from the raw z — :meth:`omega` — and by ``ekf``
        from the filtered z, whose covariance is M⁺ diag(variances) M⁺ᵀ (``variances`` (n, 3): the filter's).
        Returns z_raw, z_filtered, ω_raw, ω_filtered."""
        out = array_sample(raw, filtered, variances, offsets, self.M_pinv, dt, self._omega, self._omega_known,
                           ekf.w, ekf.P)
        self._omega_known = True
        return out


class AngularVelocityEKF:
    """ω from accelerometer-array estimates: predicted with α, corrected with the quadratic terms.

    State ω (3). Prediction ω ← ω + α dt, with α's covariance × dt² as process
    noise. Measurement: the six products h(ω) = [ω_x², ω_y², ω_z², ω_xω_y,
    ω_yω_z, ω_xω_z] solved from the readings, linearised at the prediction.
    Starting from a known ω (at rest) settles the sign the products cannot.
    """

    def __init__(self, omega0: np.ndarray | None = None, initial_var: float = 1e-4):
        self.w = np.zeros(3) if omega0 is None else np.asarray(omega0, float).copy()
        self.P = np.eye(3) * initial_var

    def step(self, z: np.ndarray, z_cov: np.ndarray, dt: float) -> np.ndarray:
        """Advance with one estimate ``z`` (12,) of covariance ``z_cov`` (12, 12); returns ω."""
        return self.run(np.asarray(z, float)[None], np.asarray(z_cov, float)[None], dt)[0]

    def run(self, zs: np.ndarray, covs: np.ndarray, dt: float) -> np.ndarray:
        """:meth:`step` over a recording: estimates (T, 12), covariances (T, 12, 12); ω after each (T, 3)."""
        return ekf_omega(np.ascontiguousarray(zs, dtype=float), np.ascontiguousarray(covs, dtype=float), dt,
                         self.w, self.P)
