"""The rest-to-rest time law every planner here uses: one quintic, written once."""

from __future__ import annotations

import numpy as np

PEAK_VELOCITY = 1.875  # the quintic's peak rate over its mean (at u = 1/2)
PEAK_ACCELERATION = 10.0 / np.sqrt(3.0)  # its peak second derivative (at u = 1/2 ± √3/6)


def quintic(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s(u) = 10u³ − 15u⁴ + 6u⁵ on [0, 1] (clipped outside), with s′ and s″: from rest to rest, no jump in
    acceleration at either end (the minimum-jerk profile)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2), 30 * u**2 * (1 - u) ** 2, 60 * u * (1 - 3 * u + 2 * u**2)
