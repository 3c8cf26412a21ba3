"""One symmetric 3×3 linear system in scalar arithmetic: a control step's damped pseudoinverse (a hand's force
from joint torques, a task velocity through a 3-row Jacobian), where ``numpy.linalg``'s dispatch costs ten times
the arithmetic (measured: ~30 µs a ``solve`` or ``inv`` against ~5 µs here)."""

from __future__ import annotations

import numpy as np


def solve_spd3(A: np.ndarray, b: np.ndarray, shift: float = 0.0) -> np.ndarray:
    """x with (A + shift·I) x = b for one symmetric 3×3 A (only its upper triangle is read), by the adjugate."""
    (a, d, e), (_, b2, f), (_, _, c) = A.tolist()
    a, b2, c = a + shift, b2 + shift, c + shift
    x, y, z = b.tolist()
    # cofactors of the symmetric matrix [[a, d, e], [d, b2, f], [e, f, c]]
    c00, c01, c02 = b2 * c - f * f, e * f - d * c, d * f - b2 * e
    c11, c12, c22 = a * c - e * e, d * e - a * f, a * b2 - d * d
    det = a * c00 + d * c01 + e * c02
    return np.array([c00 * x + c01 * y + c02 * z, c01 * x + c11 * y + c12 * z, c02 * x + c12 * y + c22 * z]) / det
