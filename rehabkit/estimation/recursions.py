"""The estimators' recursions compiled: one implementation, stepped one sample at a time online and run over a
whole recording offline (the RTS smoother's passes, the angular-velocity EKF over smoothed readings), where a
Python loop per sample cost ~2 s of a CaPaMan run's finishing (19,000 samples); and an accelerometer array's
whole online sample in one call, where numpy's per-call dispatch on 12-vectors cost more than the arithmetic.
Scalar loops only: they compile in about a second on first use, where numba's array operations and LAPACK
bindings took ~10 s for the EKF."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rehabkit.numerics.triangular import backward_solve, cholesky, forward_solve


@njit(cache=True, nogil=True)
def kalman_filter(z, value, rate, p11, p12, p22, log_scale, q, r, dt, adaptive, gain, max_log,
                  filt, pred):  # pragma: no cover - compiled
    """Predict and correct with each of ``z`` (T, count, axes), the state (value, rate, covariance entries
    p11, p12, p22 per sensor and axis; log-scale per sensor) updated in place. With T-long ``filt`` and
    ``pred`` (5, T, count, axes) it keeps each sample's corrected and predicted state (else pass empty ones)."""
    count, axes = value.shape
    keep = filt.shape[1] > 0
    for t in range(z.shape[0]):
        for i in range(count):
            s = np.exp(log_scale[i]) if adaptive else 1.0
            nis = 0.0
            for a in range(axes):
                v = value[i, a] + dt * rate[i, a]
                c11 = p11[i, a] + dt * (2.0 * p12[i, a] + dt * p22[i, a]) + s * q[0]
                c12 = p12[i, a] + dt * p22[i, a] + s * q[1]
                c22 = p22[i, a] + s * q[2]
                if keep:
                    pred[0, t, i, a], pred[1, t, i, a], pred[2, t, i, a] = v, rate[i, a], c11
                    pred[3, t, i, a], pred[4, t, i, a] = c12, c22
                S = c11 + r[a]
                k1, k2 = c11 / S, c12 / S
                e = z[t, i, a] - v
                nis += e * e / S
                value[i, a], rate[i, a] = v + k1 * e, rate[i, a] + k2 * e
                p11[i, a], p12[i, a], p22[i, a] = c11 - k1 * c11, c12 - k1 * c12, c22 - k2 * c12
                if keep:
                    filt[0, t, i, a], filt[1, t, i, a], filt[2, t, i, a] = value[i, a], rate[i, a], p11[i, a]
                    filt[3, t, i, a], filt[4, t, i, a] = p12[i, a], p22[i, a]
            if adaptive:
                log_scale[i] = min(max(log_scale[i] + gain * (nis / axes - 1.0), 0.0), max_log)


@njit(cache=True, nogil=True)
def rts_backward(filt, pred, dt):  # pragma: no cover - compiled
    """The smoother's backward pass over the filter's states: smoothed values (T, count, axes)."""
    _, T, count, axes = filt.shape
    out = np.empty((T, count, axes))
    for i in range(count):
        for a in range(axes):
            vs, rs = filt[0, T - 1, i, a], filt[1, T - 1, i, a]
            out[T - 1, i, a] = vs
            for k in range(T - 2, -1, -1):
                p11, p12, p22 = filt[2, k, i, a], filt[3, k, i, a], filt[4, k, i, a]
                e, f, g = pred[2, k + 1, i, a], pred[3, k + 1, i, a], pred[4, k + 1, i, a]
                # G = P(k) Aᵀ P⁻(k+1)⁻¹, A = [[1, dt], [0, 1]], 2×2 in closed form
                m11, m12, m21, m22 = p11 + dt * p12, p12, p12 + dt * p22, p22
                det = e * g - f * f
                g11, g12 = (m11 * g - m12 * f) / det, (m12 * e - m11 * f) / det
                g21, g22 = (m21 * g - m22 * f) / det, (m22 * e - m21 * f) / det
                dv, dr = vs - pred[0, k + 1, i, a], rs - pred[1, k + 1, i, a]
                vs = filt[0, k, i, a] + g11 * dv + g12 * dr
                rs = filt[1, k, i, a] + g21 * dv + g22 * dr
                out[k, i, a] = vs
    return out


@njit(cache=True, nogil=True)
def ekf_omega(zs, covs, dt, w, P):  # pragma: no cover - compiled
    """The angular-velocity EKF (:class:`~rehabkit.estimation.rigid_body.AngularVelocityEKF`) over estimates
    ``zs`` (T, 12) of covariances ``covs`` (T, 12, 12), from ω ``w`` and its covariance ``P`` (both updated in
    place); ω after each (T, 3). K = P Hᵀ S⁻¹ through S's Cholesky factor; a singular S (at rest, H = 0, with
    noiseless readings: the gain is 0 there) is solved with a tiny ridge, as a pseudo-inverse would."""
    out = np.empty((zs.shape[0], 3))
    H = np.zeros((6, 3))
    h = np.empty(6)
    HP = np.empty((6, 3))
    S = np.empty((6, 6))
    for t in range(zs.shape[0]):
        for i in range(3):
            w[i] += zs[t, 3 + i] * dt
            for j in range(3):
                P[i, j] += covs[t, 3 + i, 3 + j] * dt * dt
        x, y, c = w[0], w[1], w[2]
        h[0], h[1], h[2], h[3], h[4], h[5] = x * x, y * y, c * c, x * y, y * c, x * c
        H[0, 0], H[1, 1], H[2, 2] = 2 * x, 2 * y, 2 * c
        H[3, 0], H[3, 1], H[4, 1], H[4, 2], H[5, 0], H[5, 2] = y, x, c, y, c, x
        for i in range(6):
            for j in range(3):
                HP[i, j] = H[i, 0] * P[0, j] + H[i, 1] * P[1, j] + H[i, 2] * P[2, j]
        for i in range(6):
            for j in range(6):
                S[i, j] = HP[i, 0] * H[j, 0] + HP[i, 1] * H[j, 1] + HP[i, 2] * H[j, 2] + covs[t, 6 + i, 6 + j]
        L = cholesky(S)
        if L.shape[0] == 0:
            ridge = 1e-12 * (1.0 + S[0, 0] + S[1, 1] + S[2, 2] + S[3, 3] + S[4, 4] + S[5, 5])
            for i in range(6):
                S[i, i] += ridge
            L = cholesky(S)
        X = forward_solve(L, HP)  # S⁻¹ H P column by column; K = (S⁻¹ H P)ᵀ, S and P symmetric
        for j in range(3):  # (element by element: numba's slice assignment takes seconds to compile)
            col = backward_solve(L, X[:, j].copy())
            for i in range(6):
                X[i, j] = col[i]
        for j in range(3):  # w += K (z − h)
            acc = 0.0
            for i in range(6):
                acc += X[i, j] * (zs[t, 6 + i] - h[i])
            w[j] += acc
        for i in range(3):  # P −= K H P
            for j in range(3):
                acc = 0.0
                for k in range(6):
                    acc += X[k, i] * HP[k, j]
                P[i, j] -= acc
        out[t, 0], out[t, 1], out[t, 2] = w[0], w[1], w[2]
    return out


@njit(cache=True, nogil=True)
def omega_from_products(z, dt, prev, known):  # pragma: no cover - compiled
    """ω from the quadratic terms of ``z`` (12,) (see :mod:`~rehabkit.estimation.rigid_body`), its overall sign
    continuous with the previous estimate ``prev`` advanced by α dt when ``known``; ``prev`` takes the new one."""
    sx, sy, sz = math.sqrt(max(z[6], 0.0)), math.sqrt(max(z[7], 0.0)), math.sqrt(max(z[8], 0.0))
    # signs of (ω_y, ω_z) relative to ω_x from the products (of ω_z to ω_y when ω_x is zero); a zero product fits +1
    if sx < 1e-9:
        sz = -sz if z[10] < 0 else sz
    else:
        sy, sz = -sy if z[9] < 0 else sy, -sz if z[11] < 0 else sz
    if known and sx * (prev[0] + z[3] * dt) + sy * (prev[1] + z[4] * dt) + sz * (prev[2] + z[5] * dt) < 0:
        sx, sy, sz = -sx, -sy, -sz
    prev[0], prev[1], prev[2] = sx, sy, sz
    return prev.copy()


@njit(cache=True, nogil=True)
def array_sample(raw, filtered, variances, offsets, M_pinv, dt, prev, known, w, P):  # pragma: no cover - compiled
    """One sample of an accelerometer array online: z from the raw and from the filtered readings (n, 3) less the
    offsets, ω from the raw z's products (:func:`omega_from_products`) and by the EKF (:func:`ekf_omega`, state
    ``w``, ``P``) from the filtered z, of covariance M⁺ diag(variances) M⁺ᵀ. Returns z_raw, z_f, ω_raw, ω_f."""
    m, n = M_pinv.shape[0], raw.shape[0]
    z_raw, z_f, cov = np.zeros(m), np.zeros((1, m)), np.zeros((1, m, m))  # (z_f, cov: a one-sample recording)
    for i in range(m):
        for s in range(n):
            for a in range(3):
                k = 3 * s + a
                z_raw[i] += M_pinv[i, k] * (raw[s, a] - offsets[s, a])
                z_f[0, i] += M_pinv[i, k] * (filtered[s, a] - offsets[s, a])
                mv = M_pinv[i, k] * variances[s, a]
                for j in range(m):
                    cov[0, i, j] += mv * M_pinv[j, k]
    w_raw = omega_from_products(z_raw, dt, prev, known)
    return z_raw, z_f[0], w_raw, ekf_omega(z_f, cov, dt, w, P)[0]
