"""Kalman filter with the constant-rate model Carbone et al. use per accelerometer.

Each measured axis has a value and its rate of change: state [a_x, ȧ_x, a_y,
ȧ_y, a_z, ȧ_z], A = blocks of [[1, Δt], [0, 1]], B = 0, G = I, process noise
Q = blocks of [[μ1², μ1μ2], [μ1μ2, μ2²]], observation C picking the values,
R = diag(σ²). The filter here runs many such sensors at once (one state row
each), all with the same model parameters.

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

from rehabkit.estimation.recursions import kalman_filter, rts_backward


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


class KalmanBank:
    """``count`` independent filters of one model, stepped together.

    A, Q and R are block-diagonal per axis and the prior is too, so the covariance stays so: each axis is a
    two-state filter of its own (coupled only by the adaptive scale, per sensor). They are stepped as such —
    the three distinct entries of each axis' 2×2 covariance as (count, axes) arrays, a dozen elementwise
    operations a sample, compiled (:mod:`rehabkit.estimation.recursions`) — the same filter as the 6×6 matrices
    the model describes (``P``, ``x`` give them), at a fraction of the cost of batched 6×6 products and inverses.
    """

    def __init__(self, model: ConstantRateModel, count: int, adaptive: bool = False, gain: float = 0.05,
                 max_scale: float = 1e6):
        self.model = model
        axes = model.axes
        self.value, self.rate = np.zeros((count, axes)), np.zeros((count, axes))
        # per axis [[p11, p12], [p12, p22]]; vague prior: the first samples dominate
        self.p11, self.p22 = np.full((count, axes), 10.0), np.full((count, axes), 10.0)
        self.p12 = np.zeros((count, axes))
        self._q = np.array([model.mu_value**2, model.mu_value * model.mu_rate, model.mu_rate**2])
        self._r = np.asarray(model.sigma, float) ** 2
        self.started = False
        self.adaptive, self.gain, self.max_log = adaptive, gain, float(np.log(max_scale))
        self.log_scale = np.zeros(count)

    @property
    def x(self) -> np.ndarray:
        """States (count, 2·axes): [a_x, ȧ_x, a_y, ȧ_y, …]."""
        return np.stack([self.value, self.rate], axis=2).reshape(len(self.value), -1)

    @property
    def P(self) -> np.ndarray:  # noqa: N802 (the filter's name for it)
        """Covariances (count, 2·axes, 2·axes), block-diagonal."""
        count, axes = self.value.shape
        out = np.zeros((count, 2 * axes, 2 * axes))
        i = 2 * np.arange(axes)
        out[:, i, i], out[:, i, i + 1], out[:, i + 1, i], out[:, i + 1, i + 1] = self.p11, self.p12, self.p12, self.p22
        return out

    @property
    def value_variance(self) -> np.ndarray:
        """Variance of each filtered value (count, axes)."""
        return self.p11

    def step(self, z: np.ndarray) -> np.ndarray:
        """Predict, then correct with measurements ``z`` (count, axes); returns the filtered values."""
        if not self.started:  # start at the first measurement, rates zero
            self.value[:] = z
            self.started = True
            return z.copy()
        self._run(np.ascontiguousarray(z, dtype=float)[None], _NONE, _NONE)
        return self.value.copy()

    def _run(self, z: np.ndarray, filt: np.ndarray, pred: np.ndarray) -> None:
        kalman_filter(z, self.value, self.rate, self.p11, self.p12, self.p22, self.log_scale, self._q, self._r,
                      self.model.dt, self.adaptive, self.gain, self.max_log, filt, pred)


_NONE = np.zeros((5, 0, 0, 0))  # no per-sample states kept


def rts_smooth(model: ConstantRateModel, z: np.ndarray, adaptive: bool = False) -> np.ndarray:
    """Offline Rauch–Tung–Striebel smoothing of a recording (T, count, axes) with the same model.

    The forward pass is the filter above; the backward pass corrects each
    estimate with everything measured after it, x_s(k) = x(k) + G (x_s(k+1) − x⁻(k+1)),
    G = P(k) Aᵀ P⁻(k+1)⁻¹ — per axis, 2×2, in closed form, for all sensors and axes at once. For validating
    recorded runs, as the paper does, not for control.
    """
    z = np.ascontiguousarray(z, dtype=float)
    bank = KalmanBank(model, z.shape[1], adaptive=adaptive)
    bank.step(z[0])
    filt, pred = np.empty((5, *z.shape)), np.empty((5, *z.shape))
    filt[:, 0] = bank.value, bank.rate, bank.p11, bank.p12, bank.p22
    bank._run(z[1:], filt[:, 1:], pred[:, 1:])
    return rts_backward(filt, pred, model.dt)
