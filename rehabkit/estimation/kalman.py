"""Kalman filter with the constant-rate model Carbone et al. use per accelerometer.

Each measured axis has a value and its rate of change: state [a_x, ȧ_x, a_y,
ȧ_y, a_z, ȧ_z], A = blocks of [[1, Δt], [0, 1]], B = 0, G = I, process noise
Q = blocks of [[μ1², μ1μ2], [μ1μ2, μ2²]], observation C picking the values,
R = diag(σ²). The filter here runs many such sensors at once (one state row
each); the model matrices are shared.

With ``adaptive`` each sensor's process noise is scaled to keep the filter
consistent: the normalised innovation squared (NIS) has mean 3 (three axes)
when the model fits, so log(scale) moves by ``gain`` · (NIS/3 − 1) every
sample, between 0 (Table 1's Q, the floor) and ``max_scale``. The filter then
smooths as the paper's while the signal changes slowly and follows quick
motions instead of lagging behind them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ConstantRateModel:
    """The model's parameters (the paper's Table 1 by default).

    Attributes:
        dt: Sample period [s].
        mu_value: μ_m1, prediction uncertainty of the value [m/s²].
        mu_rate: μ_m2, prediction uncertainty of its rate [m/s³].
        sigma: σ of the measurement noise per axis [m/s²].
        axes: Measured axes per sensor.
    """

    dt: float
    mu_value: float = 0.01
    mu_rate: float = 0.05
    sigma: tuple[float, ...] = (0.5, 0.5, 0.5)
    axes: int = 3

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A, Q, C, R."""
        n = self.axes
        block = np.array([[1.0, self.dt], [0.0, 1.0]])
        q = np.array([[self.mu_value**2, self.mu_value * self.mu_rate],
                      [self.mu_value * self.mu_rate, self.mu_rate**2]])
        A, Q = np.kron(np.eye(n), block), np.kron(np.eye(n), q)
        C = np.zeros((n, 2 * n))
        C[np.arange(n), 2 * np.arange(n)] = 1.0
        R = np.diag(np.asarray(self.sigma, float) ** 2)
        return A, Q, C, R


class KalmanBank:
    """``count`` independent filters of one model, stepped together."""

    def __init__(self, model: ConstantRateModel, count: int, adaptive: bool = False, gain: float = 0.05,
                 max_scale: float = 1e6):
        self.model = model
        self.A, self.Q, self.C, self.R = model.matrices()
        n = self.A.shape[0]
        self.x = np.zeros((count, n))
        self.P = np.tile(np.eye(n) * 10.0, (count, 1, 1))  # vague prior: the first samples dominate
        self.started = False
        self.adaptive, self.gain, self.max_log = adaptive, gain, float(np.log(max_scale))
        self.log_scale = np.zeros(count)

    def step(self, z: np.ndarray) -> np.ndarray:
        """Predict, then correct with measurements ``z`` (count, axes); returns the filtered values."""
        A, Q, C, R = self.A, self.Q, self.C, self.R
        if not self.started:  # start at the first measurement, rates zero
            self.x[:, ::2] = z
            self.started = True
            return z.copy()
        x = self.x @ A.T  # prediction (9)
        scale = np.exp(self.log_scale)[:, None, None] if self.adaptive else 1.0
        P = A @ self.P @ A.T + scale * Q
        S = C @ P @ C.T + R  # correction (10)
        S_inv = np.linalg.inv(S)
        K = P @ C.T @ S_inv
        innovation = z - x @ C.T
        if self.adaptive:
            nis = np.einsum("ki,kij,kj->k", innovation, S_inv, innovation)
            self.log_scale = np.clip(self.log_scale + self.gain * (nis / self.model.axes - 1.0), 0.0, self.max_log)
        x = x + np.einsum("kij,kj->ki", K, innovation)
        self.P = P - K @ C @ P
        self.x = x
        return x @ C.T


def rts_smooth(model: ConstantRateModel, z: np.ndarray, adaptive: bool = False) -> np.ndarray:
    """Offline Rauch–Tung–Striebel smoothing of a recording (T, count, axes) with the same model.

    The forward pass is the filter above; the backward pass corrects each
    estimate with everything measured after it, x_s(k) = x(k) + G (x_s(k+1) − x⁻(k+1)),
    G = P(k) Aᵀ P⁻(k+1)⁻¹. For validating recorded runs, as the paper does, not for control.
    """
    bank = KalmanBank(model, z.shape[1], adaptive=adaptive)
    A = bank.A
    xs, Ps, xp, Pp = [], [], [], []
    for k, zk in enumerate(z):
        if k:
            scale = np.exp(bank.log_scale)[:, None, None] if adaptive else 1.0
            xp.append(bank.x @ A.T)
            Pp.append(A @ bank.P @ A.T + scale * bank.Q)
        bank.step(zk)
        xs.append(bank.x.copy())
        Ps.append(bank.P.copy())
    x_s = xs[-1]
    out = [x_s @ bank.C.T]
    for k in range(len(z) - 2, -1, -1):
        G = Ps[k] @ A.T @ np.linalg.inv(Pp[k])
        x_s = xs[k] + np.einsum("nij,nj->ni", G, x_s - xp[k])
        out.append(x_s @ bank.C.T)
    return np.array(out[::-1])
