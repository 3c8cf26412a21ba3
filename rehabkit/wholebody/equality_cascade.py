"""The cascade's common case in one compiled call: every level's equality-constrained optimum.

At a standstill or in smooth motion no inequality is active, and each level's QP is then
solved by one KKT system (its damped task, the higher levels' achieved task velocities as
equalities). Done level by level from Python, the numpy calls around the four LAPACK
solves cost more than the solves (~130 of ~185 us a cycle for COMAN); compiled with numba,
the whole sequence is one call, written in loops (numba compiles matrix products and slice assignments in
seconds each: ~10 s on first use, ~3 s without them). It stops at the first level whose optimum breaks an
inequality (or whose system is singular) and says so: the caller finishes that level and
the ones below with the QP solver.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from rehabkit.numerics import triangular as tri

FEASIBLE_TOL = 1e-9
CONSISTENT_TOL = 1e-7


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
            P = np.zeros((n, n))
            q = np.zeros(n)
            for r in range(start, stop):
                for i in range(n):
                    ari = A[r, i]
                    if ari != 0.0:
                        q[i] += ari * b[r]
                        for j in range(n):
                            P[i, j] += ari * A[r, j]
            for i in range(n):
                P[i, i] += reg
        else:
            stop = start
            P = metric.copy()
            q = np.zeros(n)
        L = tri.cholesky_sparse(P)  # P is mostly zero (each task moves few joints): so are L and its solves
        if L.shape[0] == 0:  # not positive definite: the QP solver handles it
            return V, k
        rhs = np.empty((n, m + 1))
        for i in range(n):
            for j in range(m):
                rhs[i, j] = A[j, i]
            rhs[i, m] = q[i]
        Z = tri.forward_solve_sparse(L, rhs)  # [Y | y]
        y = Z[:, m].copy()
        if m:
            S = np.zeros((m, m))
            g = np.empty((m, 1))
            for i in range(m):
                gi = -e[i]
                for r in range(n):
                    gi += Z[r, i] * y[r]
                g[i, 0] = gi
                for j in range(i + 1):
                    s = 0.0
                    for r in range(n):
                        s += Z[r, i] * Z[r, j]
                    S[i, j] = s
                    S[j, i] = s
            Ls = tri.cholesky(S)
            if Ls.shape[0] == 0:  # the rows above are (numerically) dependent: the QP solver
                return V, k
            lam = tri.backward_solve(Ls, tri.forward_solve(Ls, g)[:, 0])
            for r in range(n):
                s = 0.0
                for i in range(m):
                    s += Z[r, i] * lam[i]
                y[r] -= s
        v = tri.backward_solve_sparse(L, y)
        # the tests below only decide (against tolerances far above rounding): loops, not a BLAS call each
        for i in range(m):
            r = -e[i]
            for j in range(n):
                r += A[i, j] * v[j]
            if abs(r) > CONSISTENT_TOL:
                return V, k
        for i in range(n):
            if v[i] < lb[i] - FEASIBLE_TOL or v[i] > ub[i] + FEASIBLE_TOL:
                return V, k
        for i in range(G.shape[0]):
            r = -h[i]
            for j in range(n):
                r += G[i, j] * v[j]
            if r > FEASIBLE_TOL:
                return V, k
        for i in range(n):
            V[k, i] = v[i]
        if k < len(ends):
            for r in range(start, stop):
                s = 0.0
                for j in range(n):
                    s += A[r, j] * v[j]
                e[r] = s
        start = stop
    return V, steps
