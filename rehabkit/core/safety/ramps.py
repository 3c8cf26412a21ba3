"""The safety layer's soft start and soft stop: a ramp-in from holding the start posture to the controller's torque,
and a ramp-out back to holding the posture, each a half-cosine blend (no step in the torque nor in its rate)."""

from __future__ import annotations

import math

import numpy as np

from rehabkit.core.safety.event import SafetyEvent


def _blend(s: float) -> float:
    """Half-cosine from 0 to 1: no jump in the torque's rate at either end of a ramp."""
    return 0.5 - 0.5 * math.cos(math.pi * min(max(s, 0.0), 1.0))


class Ramps:
    """Ramp-in and ramp-out of :class:`~rehabkit.core.safety.layer.SafetyLayer`: ``hold(posture, q, qd)`` is the
    torque holding a posture, ``note`` keeps the interventions."""

    RUN_STATE_FIELDS = ("ramp_in", "_ramp_in_noted", "ramp_from", "start_q")  # (a snapshot's)

    def __init__(self, config, hold, note):
        self.config, self.hold, self.note = config, hold, note
        self.ramp_in, self._ramp_in_noted = config.ramp_in_s, False
        self.ramp_from: tuple[float, float, np.ndarray] | None = None  # ramp-out: (start, length, posture)
        self.start_q: np.ndarray | None = None  # the posture the ramp-in holds first (the first step's)

    def require_ramp_in(self, seconds: float) -> bool:
        """Ramp in at least this long (the first session after an e-stop was cleared); whether that changed it."""
        if seconds > self.ramp_in:
            self.ramp_in = seconds
            return True
        return False

    def begin_ramp_out(self, t: float, q: np.ndarray) -> bool:
        """Start the soft stop: over ``ramp_out_s`` the torque blends into holding posture ``q``; whether it
        started (there is one, and not already)."""
        if self.ramp_from is not None or self.config.ramp_out_s <= 0:
            return False
        self.ramp_from = (t, self.config.ramp_out_s, np.array(q, float))
        self.note(SafetyEvent(t, "ramp-out", None, None, None,
                              f"t={t:.3f}s: ramp-out over {self.config.ramp_out_s:g} s to holding the posture",
                              {"duration_s": self.config.ramp_out_s}, level="INFO"))
        return True

    def due(self, t: float) -> bool:
        """Whether a ramp shapes the torque at ``t``."""
        return t < self.ramp_in or self.ramp_from is not None

    def apply(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> None:
        """Blend ``tau`` (in place) with holding the posture the ramp is from or to."""
        if self.ramp_from is not None:
            t0, length, posture = self.ramp_from
            s = 1.0 - _blend((t - t0) / length)
        else:
            if not self._ramp_in_noted:
                self._ramp_in_noted = True
                self.note(SafetyEvent(t, "ramp-in", None, None, None,
                                      f"t={t:.3f}s: ramp-in over {self.ramp_in:g} s from holding the start posture",
                                      {"duration_s": self.ramp_in}, level="INFO"))
            posture, s = self.start_q, _blend(t / self.ramp_in)
        hold = self.hold(posture, q, qd)
        tau *= s
        tau += (1.0 - s) * hold
