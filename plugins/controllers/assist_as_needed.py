"""Assist-as-needed impedance control: the robot's stiffness grows while the person falls behind and
fades while they keep up (the error-based adaptation of Emken et al., 2007, in continuous time), and
a learned assisting force with forgetting supplies what the person persistently lacks (after
Wolbrecht et al., 2008), so help is given where and while it is needed.

With a Cartesian reference (e.g. L-Exos) the impedance acts at the hand:

    τ = Jᵀ (K e + D ė + F_a) + N (k_n (q_c − q) − d_n q̇) + g(q),   e = x_r − x,   N = I − J⁺J
    K̇ = −K / T_f + γ · max(0, ‖e‖ − e_0),   K ∈ [K_min, K_max],   D = 2ζ √(K m)
    Ḟ_a = γ_a e − F_a / T_f,   ‖F_a‖ ≤ F_max

where N keeps the redundant elbow swivel near the middle of the ranges and g(q) carries the robot's own
weight (not the person's). With a joint reference (e.g. HIT) the same law runs per joint. The robot
never pushes harder than K_max allows; with K near K_min it is nearly transparent and the person does
the movement.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from pydantic import Field, model_validator

from rehabkit.plugin import Context, Controller, Metric, StrictModel, hookimpl

SERIES_EVERY = 10


class AssistAsNeededConfig(StrictModel):
    """Impedance bounds and adaptation (N/m at the hand for Cartesian references, N·m/rad per joint otherwise)."""

    k_min: float = Field(50.0, ge=0, description="least stiffness (transparent when the person keeps up)")
    k_max: float = Field(1500.0, gt=0, description="most stiffness (full assistance)")
    k_start: float | None = Field(None, ge=0, description="stiffness at the start (default: k_min)")
    forgetting_s: float = Field(2.0, gt=0, description="T_f: how fast assistance fades while the error is small")
    gain: float = Field(2.0e5, ge=0, description="γ: stiffness growth per unit error beyond the dead band, per s")
    dead_band: float = Field(0.005, ge=0, description="e_0: error tolerated without more help [m] or [rad]")
    damping_ratio: float = Field(0.7, ge=0, description="ζ")
    mass: float = Field(1.5, gt=0, description="m: effective mass [kg] or inertia [kg·m²] the damping is set for")
    force_gain: float = Field(1000.0, ge=0, description="γ_a: growth of the learned assisting force per unit error "
                                                        "[N/(m·s)] or [N·m/(rad·s)]")
    force_max: float = Field(40.0, ge=0, description="F_max: largest learned assisting force [N] or torque [N·m]")
    null_stiffness: float = Field(5.0, ge=0, description="k_n: joints toward mid-range in the null space [N·m/rad]")
    null_damping: float = Field(1.0, ge=0, description="d_n [N·m·s/rad]")
    gravity_compensation: bool = True

    @model_validator(mode="after")
    def _bounds(self) -> AssistAsNeededConfig:
        if self.k_min > self.k_max:
            raise ValueError(f"k_min ({self.k_min}) must not exceed k_max ({self.k_max})")
        if self.k_start is not None and not self.k_min <= self.k_start <= self.k_max:
            raise ValueError("k_start must lie in [k_min, k_max]")
        return self


class AssistAsNeeded(Controller):
    """Impedance control whose stiffness follows the tracking error; see the module docstring."""

    tunable = ("k_min", "k_max", "gain", "dead_band", "force_gain", "force_max", "forgetting_s")
    metrics = (Metric("aan_stiffness_mean", "N/m or N·m/rad", outcome=True, description="mean assisting stiffness"),
               Metric("aan_stiffness_max", "N/m or N·m/rad", description="largest assisting stiffness"))

    def __init__(self, config: AssistAsNeededConfig, context: Context):
        robot = context.robot.model
        self.reference = context.reference_space  # takes either space: an instance attribute, read by the runner
        self.cfg = config
        self.dt = context.control_dt
        n = robot.dof
        self.model, self.data = robot.pin_model, robot.pin_model.createData()
        self.frame = robot.ee_frame_id
        self.cartesian = self.reference == "cartesian"
        start = config.k_start if config.k_start is not None else config.k_min
        self.k = float(start) if self.cartesian else np.full(n, float(start))
        self.f_a = np.zeros(3 if self.cartesian else n)  # the learned assisting force
        lim = robot.limits
        self.centre = (lim.lower + lim.upper) / 2
        self.eye = np.eye(n)
        self.zero = np.zeros(n)
        self.step = 0
        self._t: list[float] = []
        self._k: list[float] = []
        self._k_sum = 0.0

    def tune(self, values: dict[str, float]) -> None:
        super().tune(values)
        cfg = self.cfg.model_copy(update={k: float(v) for k, v in values.items()})
        if cfg.k_min > cfg.k_max or cfg.forgetting_s <= 0:
            raise ValueError(f"assist-as-needed: tuned to k_min {cfg.k_min:g} > k_max {cfg.k_max:g} or "
                             f"forgetting_s {cfg.forgetting_s:g} <= 0")
        self.cfg = cfg

    def _adapt(self, error):
        c = self.cfg
        grow = c.gain * np.maximum(0.0, np.abs(error) - c.dead_band)
        k = self.k + self.dt * (-self.k / c.forgetting_s + grow)
        return np.clip(k, c.k_min, c.k_max)

    def _learn(self, e: np.ndarray) -> None:
        c = self.cfg
        self.f_a += self.dt * (c.force_gain * e - self.f_a / c.forgetting_s)
        size = float(np.linalg.norm(self.f_a)) if self.cartesian else None
        if self.cartesian and size > c.force_max:
            self.f_a *= c.force_max / size
        elif not self.cartesian:
            np.clip(self.f_a, -c.force_max, c.force_max, out=self.f_a)

    def compute(self, t, q, qd, x_r, xd_r, xdd_r):
        c = self.cfg
        if self.cartesian:
            J = pin.computeFrameJacobian(self.model, self.data, q, self.frame, pin.LOCAL_WORLD_ALIGNED)[:3]
            e = x_r - self.data.oMf[self.frame].translation
            self.k = float(self._adapt(np.linalg.norm(e)))
            self._learn(e)
            d = 2 * c.damping_ratio * math.sqrt(self.k * c.mass)
            tau = J.T @ (self.k * e + d * (xd_r - J @ qd) + self.f_a)
            null = self.eye - np.linalg.pinv(J) @ J
            tau += null @ (c.null_stiffness * (self.centre - q) - c.null_damping * qd)
            level = self.k
        else:
            e = x_r - q
            self.k = self._adapt(e)
            self._learn(e)
            d = 2 * c.damping_ratio * np.sqrt(self.k * c.mass)
            tau = self.k * e + d * (xd_r - qd) + self.f_a
            level = float(np.mean(self.k))
        if c.gravity_compensation:
            tau = tau + pin.rnea(self.model, self.data, q, self.zero, self.zero)
        self._k_sum += level
        if self.step % SERIES_EVERY == 0:
            self._t.append(t)
            self._k.append(level)
        self.step += 1
        return tau

    def run_metrics(self, trace) -> dict[str, float]:
        return {"aan_stiffness_mean": self._k_sum / max(1, self.step),
                "aan_stiffness_max": float(max(self._k, default=0.0))}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {"controller/assist_stiffness": (np.asarray(self._t), np.asarray(self._k))}


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("assist-as-needed", config=AssistAsNeededConfig, factory=AssistAsNeeded)
