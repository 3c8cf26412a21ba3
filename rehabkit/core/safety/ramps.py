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
    """Ramp-in and ramp-out of :class:`~rehabkit.core.safety.layer.SafetyLayer` (its state: ``_ramp_in``,
    ``_ramp_from``, ``_start_q``; its hold torque and its log of interventions)."""

    def require_ramp_in(self, seconds: float) -> None:
        """Ramp in at least this long (the first session after an e-stop was cleared)."""
        if seconds > self._ramp_in:
            self._ramp_in, self._plain = seconds, False

    def begin_ramp_out(self, t: float, q: np.ndarray) -> None:
        """Start the soft stop: over ``ramp_out_s`` the torque blends into holding posture ``q``."""
        if self._ramp_from is None and self.config.ramp_out_s > 0 and self.tripped_at is None:
            self._ramp_from = (t, self.config.ramp_out_s, np.array(q, float))
            self._plain = False
            self._note(SafetyEvent(t, "ramp-out", None, None, None,
                                   f"t={t:.3f}s: ramp-out over {self.config.ramp_out_s:g} s to holding the posture",
                                   {"duration_s": self.config.ramp_out_s}, level="INFO"))

    def _ramp(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> None:
        if self._ramp_from is not None:
            t0, length, posture = self._ramp_from
            s = 1.0 - _blend((t - t0) / length)
        else:
            if not self._ramp_in_noted:
                self._ramp_in_noted = True
                self._note(SafetyEvent(t, "ramp-in", None, None, None,
                                       f"t={t:.3f}s: ramp-in over {self._ramp_in:g} s from holding the start posture",
                                       {"duration_s": self._ramp_in}, level="INFO"))
            posture, s = self._start_q, _blend(t / self._ramp_in)
        hold = self._hold_torque(posture, q, qd)
        tau *= s
        tau += (1.0 - s) * hold

