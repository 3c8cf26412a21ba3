"""The cascade's common case in one compiled call: every level's equality-constrained optimum.

At a standstill or in smooth motion no inequality is active, and each level's QP is then
solved by one KKT system (its damped task, the higher levels' achieved task velocities as
equalities). Done level by level from Python, the numpy calls around the four LAPACK
solves cost more than the solves (~130 of ~185 us a cycle for COMAN); compiled with numba,
the whole sequence is one call. It stops at the first level whose optimum breaks an
inequality (or whose system is singular) and says so: the caller finishes that level and
the ones below with the QP solver.
"""

from __future__ import annotations

import numpy as np
from numba import njit

FEASIBLE_TOL = 1e-9
CONSISTENT_TOL = 1e-7


@njit(cache=True, nogil=True)
def _cholesky(M):  # pragma: no cover - compiled
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
def _forward(L, B):  # pragma: no cover - compiled
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
def _backward(L, y):  # pragma: no cover - compiled
    """L⁻ᵀ y for lower-triangular L."""
    n = len(y)
    x = y.copy()
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            x[i] -= L[k, i] * x[k]
        x[i] /= L[i, i]
    return x


@njit(cache=True, nogil=True)
def equality_cascade(A, b, ends, reg, metric, use_metric, lb, ub, G, h):  # pragma: no cover - compiled
    """Solutions of the steps (levels, then the least-``metric`` step if ``use_metric``) while feasible.

    ``A``, ``b``: every level's rows stacked, level k's rows ending at ``ends[k]``.
    Returns ``(V, done)``: ``V[k]`` step k's solution for ``k < done``; ``done`` is the
    number of steps solved, all of them when no inequality was in the way.

    Each step's KKT system  [P Eᵀ; E 0] [v; λ] = [q; e]  (P = A_kᵀA_k + εI, or the metric; E the rows of
    the levels above, e what they achieved) is solved by its Schur complement: with P = L Lᵀ (Cholesky),
    Y = L⁻¹Eᵀ and y = L⁻¹q, (YᵀY) λ = Yᵀy − e and v = L⁻ᵀ(y − Yλ) — two small Cholesky factorisations
    and triangular solves, half the work of an LU of the whole KKT matrix (which this replaced: 90 us
    a cycle for COMAN).
    """
    n = A.shape[1]
    steps = len(ends) + (1 if use_metric else 0)
    V = np.zeros((steps, n))
    e = np.zeros(A.shape[0])  # the achieved task velocities of the levels above, A_j v_j
    start = 0
    for k in range(steps):
        m = start  # equality rows: every level above
        if k < len(ends):
            stop = ends[k]
            Ak, bk = A[start:stop], b[start:stop]
            P = Ak.T @ Ak
            for i in range(n):
                P[i, i] += reg
            q = Ak.T @ bk
        else:
            stop = start
            P = metric.copy()
            q = np.zeros(n)
        L = _cholesky(P)
        if L.shape[0] == 0:  # not positive definite: the QP solver handles it
            return V, k
        rhs = np.empty((n, m + 1))
        rhs[:, :m] = A[:m].T
        rhs[:, m] = q
        Z = _forward(L, rhs)  # [Y | y]
        y = np.ascontiguousarray(Z[:, m])
        if m:
            Y = np.ascontiguousarray(Z[:, :m])
            Ls = _cholesky(Y.T @ Y)
            if Ls.shape[0] == 0:  # the rows above are (numerically) dependent: the QP solver
                return V, k
            lam = _backward(Ls, _forward(Ls, (Y.T @ y - e[:m]).reshape(m, 1))[:, 0])
            y -= Y @ lam
        v = _backward(L, y)
        if m and np.max(np.abs(A[:m] @ v - e[:m])) > CONSISTENT_TOL:
            return V, k
        for i in range(n):
            if v[i] < lb[i] - FEASIBLE_TOL or v[i] > ub[i] + FEASIBLE_TOL:
                return V, k
        if G.shape[0] and np.max(G @ v - h) > FEASIBLE_TOL:
            return V, k
        V[k] = v
        if k < len(ends):
            e[start:stop] = Ak @ v
        start = stop
    return V, steps
