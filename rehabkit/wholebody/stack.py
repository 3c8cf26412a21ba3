"""A cascade of velocity-level QPs (strict priorities), and the single weighted QP it is compared with.

Each level holds equality tasks ``A v = b`` (rows already weighted: tasks sharing a level
are soft with respect to each other) and every level obeys the same inequalities
``G v ≤ h`` and bounds ``lb ≤ v ≤ ub``. Level k minimises ``½‖A_k v − b_k‖² + ½ε vᵀHv``
without changing what the levels above achieved: their task velocities, as solved, become
equality constraints of the levels below (the paper's hard priorities, eqs. 7–9). The QPs
go to ``qpsolvers`` (daqp or proxqp), warm-started from the previous cycle.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from qpsolvers import daqp_solve_qp, proxqp_solve_qp
from scipy.linalg.lapack import dgesv

from rehabkit.wholebody.equality_cascade import FEASIBLE_TOL, equality_cascade


@dataclass
class Level:
    """One priority level: stacked, weighted task rows."""

    A: np.ndarray
    b: np.ndarray


@dataclass
class Inequalities:
    """Constraints every level obeys: ``G v ≤ h`` and ``lb ≤ v ≤ ub`` (finite: a large value where free)."""

    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray


@dataclass
class StackResult:
    v: np.ndarray
    residuals: list[float] = field(default_factory=list)  # ‖A_k v − b_k‖ per level
    failed_levels: list[int] = field(default_factory=list)


# the solvers' own qpsolvers entry points: the generic dispatcher's checks cost ~75 us a call at this size
SOLVERS = {"daqp": daqp_solve_qp, "proxqp": proxqp_solve_qp}



def _qp(P, q, ineq: Inequalities, E, e, solver, init, stats: dict | None = None, try_direct: bool = True):
    """min ½vᵀPv + qᵀv s.t. E v = e and the inequalities.

    The equality-constrained optimum (one KKT solve) is tried first: when it already
    satisfies every inequality it is the QP's optimum too (the problem is convex), and
    the QP solver is only called when it does not, which at a standstill or in smooth
    motion is the exception (``try_direct=False``: the caller already knows it does not).
    """
    if not try_direct:
        return _solver(P, q, ineq, E, e, solver, init, stats)
    n = len(q)
    if E is None:
        kkt, rhs = P, -q
    else:
        m = len(E)
        kkt = np.zeros((n + m, n + m))
        kkt[:n, :n], kkt[:n, n:], kkt[n:, :n] = P, E.T, E
        rhs = np.concatenate([-q, e])
    _, _, x, info = dgesv(kkt, rhs)  # LAPACK directly: numpy's wrapper doubles the cost at this size
    v = x[:n]
    solved = info == 0 and (E is None or np.abs(E @ v - e).max() < 1e-7)  # else singular/inconsistent: solver
    if solved and np.all((v >= ineq.lb - FEASIBLE_TOL) & (v <= ineq.ub + FEASIBLE_TOL)) \
            and (not len(ineq.h) or np.all(ineq.G @ v <= ineq.h + FEASIBLE_TOL)):
        if stats is not None:
            stats["direct"] = stats.get("direct", 0) + 1
        return v
    return _solver(P, q, ineq, E, e, solver, init, stats)


@functools.cache
def _eye(n: int) -> np.ndarray:
    """The identity, shared by every cycle (nothing writes to a metric; left writable so that the compiled
    cascade has one signature for it and for an inertia matrix)."""
    return np.eye(n)


def _solver(P, q, ineq: Inequalities, E, e, solver, init, stats: dict | None):
    if stats is not None:
        stats["solver"] = stats.get("solver", 0) + 1
    G, h = (ineq.G, ineq.h) if len(ineq.h) else (None, None)
    return SOLVERS[solver](P, q, G, h, E, e, ineq.lb, ineq.ub, initvals=init)


def solve_cascade(levels: list[Level], ineq: Inequalities, reg: float = 1e-6, solver: str = "daqp",
                  warm: list[np.ndarray | None] | None = None, metric: np.ndarray | None = None,
                  stats: dict | None = None, stacked: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                  ) -> StackResult:
    """Lexicographic solution of ``levels`` (first = highest priority) under ``ineq``.

    Level k minimises its own residual (plus a small damping ½ε‖v‖² that keeps the problem
    well posed near singularities) subject to every higher level keeping the task velocity it
    achieved (``A_j v = A_j v_j``) and to the inequalities. Among all velocities that keep
    every level's result, a last step picks the one of least ½vᵀHv: with ``metric`` H the
    joint-space inertia matrix that is the kinetic energy of the paper's eq. (1), so the heavy
    pelvis is not moved for the sake of a light arm (identity: the minimum-norm solution).
    A step whose QP fails (e.g. its equalities became numerically inconsistent) is skipped
    and reported. ``stacked``: every level's rows already in one array, in order (the levels views of it), and
    the index of each level's last row + 1.
    """
    n = len(ineq.lb)
    H = _eye(n) if metric is None else metric
    if stacked is None:
        A, b = np.vstack([lv.A for lv in levels]), np.concatenate([lv.b for lv in levels])
        ends = np.cumsum([len(lv.b) for lv in levels])
    else:
        A, b, ends = stacked
    freedom_left = bool(ends[-1] < n)  # else the levels leave nothing to choose (generically)
    # the common case first: every step's equality-constrained optimum, in one compiled call
    V, done = equality_cascade(A, b, ends, reg, H, freedom_left, ineq.lb, ineq.ub, ineq.G, ineq.h)
    if stats is not None:
        stats["direct"] = stats.get("direct", 0) + done
    if done == len(V):
        if warm is not None:
            warm[:] = list(V)
        r = A @ V[-1] - b
        r *= r
        starts = np.concatenate(([0], ends[:-1]))
        return StackResult(V[-1], np.sqrt(np.add.reduceat(r, starts)).tolist())  # ‖A_k v − b_k‖
    steps: list[Level | None] = [*levels, *([None] if freedom_left else [])]  # None: the least kinetic energy
    v = np.zeros(n)
    rows: list[np.ndarray] = []
    values: list[np.ndarray] = []
    out = StackResult(v)
    for k, level in enumerate(steps):
        if k < done:
            x = V[k]
        else:  # at `done` an inequality is in the way (or the system is singular): the QP solver
            if level is None:
                P, q = H, np.zeros(n)
            else:
                P = level.A.T @ level.A
                P.flat[:: n + 1] += reg  # the damping, on the diagonal in place
                q = -level.A.T @ level.b
            E = np.vstack(rows) if rows else None
            e = np.concatenate(values) if values else None
            init = warm[k] if warm is not None and k < len(warm) else None
            x = _qp(P, q, ineq, E, e, solver, init, stats, try_direct=k > done)
        if x is None:
            out.failed_levels.append(k)
        else:
            v = x
            if warm is not None:
                while len(warm) <= k:
                    warm.append(None)
                warm[k] = x
        if level is not None:
            rows.append(level.A)
            values.append(level.A @ v)
    out.residuals = [_norm(lv.A @ v - lv.b) for lv in levels]
    out.v = v
    return out


def compile_kernels() -> None:
    """Compile (or load from numba's cache) the compiled path now, so a control loop's first cycle does not."""
    free = Inequalities(np.zeros((0, 2)), np.zeros(0), np.full(2, -1.0), np.full(2, 1.0))
    solve_cascade([Level(np.eye(1, 2), np.zeros(1))], free)


def _norm(r: np.ndarray) -> float:
    return float(np.sqrt(r @ r))


def solve_weighted(levels: list[Level], weights: list[float], ineq: Inequalities, reg: float = 1e-6,
                   solver: str = "daqp", metric: np.ndarray | None = None, stats: dict | None = None) -> StackResult:
    """All levels in one QP, level k's rows scaled by ``weights[k]`` (the soft-priority alternative)."""
    n = len(ineq.lb)
    H = np.eye(n) if metric is None else metric
    A = np.vstack([w * lv.A for w, lv in zip(weights, levels)])
    b = np.concatenate([w * lv.b for w, lv in zip(weights, levels)])
    v = _qp(A.T @ A + reg * H, -A.T @ b, ineq, None, None, solver, None, stats)
    out = StackResult(np.zeros(n) if v is None else v, failed_levels=[] if v is not None else [0])
    out.residuals = [float(np.linalg.norm(lv.A @ out.v - lv.b)) for lv in levels]
    return out
