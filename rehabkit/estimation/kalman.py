"""Kalman filter with the constant-rate model Carbone et al. use per accelerometer.

Each measured axis has a value and its rate of change: state [a_x, ȧ_x, a_y,
ȧ_y, a_z, ȧ_z], A = blocks of [[1, Δt], [0, 1]], B = 0, G = I, process noise
Q = blocks of [[μ1², μ1μ2], [μ1μ2, μ2²]], observation C picking the values,
R = diag(σ²). The filter here runs many such sensors at once (one state row
each); the model matrices are shared.
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

    def __init__(self, model: ConstantRateModel, count: int):
        self.model = model
        self.A, self.Q, self.C, self.R = model.matrices()
        n = self.A.shape[0]
        self.x = np.zeros((count, n))
        self.P = np.tile(np.eye(n) * 10.0, (count, 1, 1))  # vague prior: the first samples dominate
        self.started = False

    def step(self, z: np.ndarray) -> np.ndarray:
        """Predict, then correct with measurements ``z`` (count, axes); returns the filtered values."""
        A, Q, C, R = self.A, self.Q, self.C, self.R
        if not self.started:  # start at the first measurement, rates zero
            self.x[:, ::2] = z
            self.started = True
            return z.copy()
        x = self.x @ A.T  # prediction (9)
        P = A @ self.P @ A.T + Q
        S = C @ P @ C.T + R  # correction (10)
        K = P @ C.T @ np.linalg.inv(S)
        x = x + np.einsum("kij,kj->ki", K, z - x @ C.T)
        self.P = P - K @ C @ P
        self.x = x
        return x @ C.T
