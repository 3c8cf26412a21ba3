"""OMPL's process-wide seed, set so that each plan draws the same numbers wherever it runs."""

from __future__ import annotations

from ompl import util as ou


def seed_ompl(seed: int) -> int:
    """Reseed OMPL's process-wide seed generator; returns the seed used (OMPL ignores 0).

    Each OMPL sampler takes its seed from that generator when it is made, and a plan makes all of its own, so a
    plan reseeded first draws the same numbers whatever this process planned before (a serial sweep's later runs,
    a test after another), as in a fresh process. OMPL logs an error for a reseed after its first draw, meant for
    generators made earlier (they keep their streams): none of those takes part in a plan, so it is silenced.
    """
    seed = int(seed) % 2**32 or 2**31
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    try:
        ou.RNG.setSeed(seed)
    finally:
        ou.setLogLevel(ou.LogLevel.LOG_WARN)
    return seed
