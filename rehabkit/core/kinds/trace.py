"""A run's record at the control rate: what the plugins' ``run_metrics`` read, and what the results are made of."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Trace:
    """Everything recorded at the control rate, trimmed to the steps actually run."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    x: np.ndarray | None = None  # end effector, robot base frame (Cartesian runs)
    x_ref: np.ndarray | None = None
    tau_h: np.ndarray | None = None  # torques a (simulated) person applied at the joints
    f_h: np.ndarray | None = None  # interaction force measured [N] (a force-torque sensor, an embodied person's cuffs)
    q_ctrl: np.ndarray | None = None  # the controller's own joint reference where it exposes one (NaN elsewhere)

    def trimmed(self, n: int) -> Trace:
        return Trace(*(None if getattr(self, f) is None else getattr(self, f)[:n]
                       for f in ("t", "q", "qd", "tau", "q_ref", "qd_ref", "x", "x_ref", "tau_h", "f_h", "q_ctrl")))
