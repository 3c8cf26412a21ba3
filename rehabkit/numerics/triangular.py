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


# The same arithmetic as above, skipping the products with an exact zero of L, which leave every sum as it was (up to
# the sign of a zero): the same results at a fraction of the cost when most of L is zero, as in a whole-body stack,
# where each task moves few joints and a level's P = AᵀA + εI is mostly its diagonal. Dense factors (an estimator's)
# are better served by the plain loops, without the tests.


@njit(cache=True, nogil=True)
def cholesky_sparse(M):  # pragma: no cover - compiled
    """:func:`cholesky`, for a mostly-zero M."""
    n = M.shape[0]
    L = np.zeros((n, n))
    nz = np.empty(n, np.int64)  # the columns k < j of row j of L that are not zero
    for j in range(n):
        d = M[j, j]
        c = 0
        for k in range(j):
            ljk = L[j, k]
            if ljk != 0.0:
                d -= ljk * ljk
                nz[c] = k
                c += 1
        if d <= 1e-300:
            return np.zeros((0, 0))
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            s = M[i, j]
            for t in range(c):
                s -= L[i, nz[t]] * L[j, nz[t]]
            L[i, j] = s / L[j, j]
    return L


@njit(cache=True, nogil=True)
def forward_solve_sparse(L, B):  # pragma: no cover - compiled
    """:func:`forward_solve`, for a mostly-zero L."""
    n, c = B.shape
    X = B.copy()
    for i in range(n):
        for k in range(i):
            lik = L[i, k]
            if lik != 0.0:
                for j in range(c):
                    X[i, j] -= lik * X[k, j]
        for j in range(c):
            X[i, j] /= L[i, i]
    return X


@njit(cache=True, nogil=True)
def backward_solve_sparse(L, y):  # pragma: no cover - compiled
    """:func:`backward_solve`, for a mostly-zero L."""
    n = len(y)
    x = y.copy()
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            lki = L[k, i]
            if lki != 0.0:
                x[i] -= lki * x[k]
        x[i] /= L[i, i]
    return x
