"""One symmetric 3×3 linear system in scalar arithmetic: a control step's damped pseudoinverse (a hand's force
from joint torques, a task velocity through a 3-row Jacobian), where ``numpy.linalg``'s dispatch costs ten times
the arithmetic (measured: ~30 µs a ``solve`` or ``inv`` against ~5 µs here). The arithmetic is one function of
floats: Python calls it through :func:`solve_spd3`, and a compiled kernel (a controller's whole step) compiles it
itself, so this module stays free of numba."""

from __future__ import annotations

import numpy as np


def solve_spd3(A: np.ndarray, b: np.ndarray, shift: float = 0.0) -> np.ndarray:
    """x with (A + shift·I) x = b for one symmetric 3×3 A (only its upper triangle is read), by the adjugate."""
    (a, d, e), (_, b2, f), (_, _, c) = A.tolist()
    return np.array(adjugate_solve3(a + shift, d, e, b2 + shift, f, c + shift, *b.tolist()))


def adjugate_solve3(a, d, e, b2, f, c, x, y, z):
    """The solution of [[a, d, e], [d, b2, f], [e, f, c]] (x', y', z') = (x, y, z), on floats."""
    c00, c01, c02 = b2 * c - f * f, e * f - d * c, d * f - b2 * e  # cofactors
    c11, c12, c22 = a * c - e * e, d * e - a * f, a * b2 - d * d
    det = a * c00 + d * c01 + e * c02
    return (c00 * x + c01 * y + c02 * z) / det, (c01 * x + c11 * y + c12 * z) / det, \
        (c02 * x + c12 * y + c22 * z) / det
