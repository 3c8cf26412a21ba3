"""Small dense linear algebra compiled with numba, for kernels that solve many small systems in a loop (the
whole-body cascade, the estimators): Cholesky and triangular solves written out compile in a fraction of the
time numba's LAPACK-backed ``np.linalg`` takes (an EKF with ``inv`` and ``pinv``: ~12 s on first use) and run
without its per-call copies."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def cholesky(M):  # pragma: no cover - compiled
    """Lower factor L of a symmetric positive definite M (L Lᵀ = M), or an empty array if M is not."""
    n = M.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        d = M[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if d <= 1e-300:
            return np.zeros((0, 0))
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return L


@njit(cache=True, nogil=True)
def forward_solve(L, B):  # pragma: no cover - compiled
    """L⁻¹ B for lower-triangular L, B (n, c)."""
    n, c = B.shape
    X = B.copy()
    for i in range(n):
        for k in range(i):
            lik = L[i, k]
            for j in range(c):
                X[i, j] -= lik * X[k, j]
        for j in range(c):
            X[i, j] /= L[i, i]
    return X


@njit(cache=True, nogil=True)
def backward_solve(L, y):  # pragma: no cover - compiled
    """L⁻ᵀ y for lower-triangular L."""
    n = len(y)
    x = y.copy()
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            x[i] -= L[k, i] * x[k]
        x[i] /= L[i, i]
    return x
