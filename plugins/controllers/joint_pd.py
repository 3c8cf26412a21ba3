"""Joint-space PD with model-based feedforward from Pinocchio."""

from __future__ import annotations

from typing import Literal

import numpy as np
import pinocchio as pin
from pydantic import ConfigDict, Field

from rehabkit.plugin import Context, Controller, SettingError, StrictModel, hookimpl


class JointPDConfig(StrictModel):
    """Gains per joint (a list) or for all joints (one number); or ``gains: auto`` from the model's inertia."""

    # built where first used: the registry's model of the plugin (this one with its `type`), built as it is
    # registered, is what a scenario is validated with (~0.5 ms less of every run's start)
    model_config = ConfigDict(defer_build=True)

    gains: Literal["manual", "auto"] = Field(
        "manual", description="auto: τ = M(q)(ω²e + 2ζωė) with the joint-space inertia M(q) of the robot's model, "
                              "so every joint, light or heavy, in any posture, responds at bandwidth_hz")
    kp: float | list[float] = Field(100.0, description="stiffness [N·m/rad] (gains: manual)")
    kd: float | list[float] = Field(10.0, description="damping [N·m·s/rad] (gains: manual)")
    bandwidth_hz: float = Field(4.0, gt=0, description="gains: auto — each joint's closed-loop natural frequency [Hz]")
    damping_ratio: float = Field(1.0, gt=0, description="gains: auto — each joint's damping ratio (1: critical)")
    feedforward: Literal["gravity", "inverse-dynamics", "none"] | None = Field(
        None, description="gravity: RNEA(q, 0, 0); inverse-dynamics: RNEA(q, qd_ref, qdd_ref) with the rotors' "
                          "armature, plus the joints' declared damping and Coulomb friction at qd_ref; default: "
                          "inverse-dynamics with gains: auto (both from the model), gravity with manual gains"
    )


class JointPD(Controller):
    """Joint PD, τ = Kp(q_ref − q) + Kd(q̇_ref − q̇) + RNEA feedforward."""

    def __init__(self, config: JointPDConfig, context: Context):
        model = context.robot.model
        n = model.dof
        self.auto = config.gains == "auto"
        if self.auto:
            given = [k for k in ("kp", "kd") if k in config.model_fields_set]
            if given:
                raise SettingError(given[0], f"{' and '.join(given)} {'are' if len(given) > 1 else 'is'} computed "
                                 "from the model's inertia here (auto)", fix="leave it out, or ask for manual ones")
            w = 2 * np.pi * config.bandwidth_hz
            if w * context.control_dt > 0.3:  # a sampled PD this fast against its own period rings or diverges
                most = 0.3 / context.control_dt / 2 / np.pi
                raise SettingError("bandwidth_hz", f"{config.bandwidth_hz:g} is too high for a control period "
                                 f"of {context.control_dt * 1000:g} ms", fix=f"at most {most:.0f}")
            self.kp, self.kd = np.full(n, w * w), np.full(n, 2 * config.damping_ratio * w)  # per unit inertia
            # A joint's own damping d, compensated along the reference by the feedforward, still acts on the error
            # (d·ė): a light joint with a heavy drive (an xArm7 wrist: 1.4e-4 kg·m² against 2 N·m·s/rad) would
            # return to its reference with a time constant d / (M ω²), 23 s there. Adding the stiffness ω·d makes
            # the error's poles -ω and -(ω + d/M): every joint, light or heavy, back at the bandwidth.
            self.kp_own = w * model.dissipation.damping
        else:
            self.kp = self._gains(config.kp, n, "kp")
            self.kd = self._gains(config.kd, n, "kd")
            if context.note is not None and (said := self._ringing(context)):
                context.note(0.0, said)
        # gains from the model come with the model's feedforward: a robot's declared friction (the Z1's 1-2 N·m)
        # left to auto gains alone held it 2.2° off its postures
        self.mode = config.feedforward or ("inverse-dynamics" if self.auto else "gravity")
        losses = model.dissipation  # (its arrays held here: the loop pays two products a step, not a call)
        self._damping = losses.damping if np.any(losses.damping) else None
        self._friction = (losses.friction, losses.fade) if np.any(losses.friction) else None
        self._inverse_dynamics, self._gravity = self.mode == "inverse-dynamics", self.mode == "gravity"
        self._gravity_torque = context.robot.gravity_torque  # the robot's own model (Pinocchio for serial arms)
        if self._inverse_dynamics or self.auto:
            self._model = model.pin_model
            self._data = self._model.createData()

    def _ringing(self, context: Context) -> str:
        """The joints whose damping gain a control period cannot apply to their inertia (taken mid-range): kd·dt/I
        above 2 — the drive's own damping d counted as d·dt of inertia — rings and trips the speed limit at once
        (an SO-100's gripper at the default kd: 833). Said at the setting, with the most it can take."""
        robot, dt = context.robot, context.control_dt
        model = robot.model
        try:
            inertia = 1.0 / np.diag(np.linalg.inv(robot.mass_matrix((model.limits.lower + model.limits.upper) / 2)))
        except Exception:  # noqa: BLE001 (a robot without a dynamic model: nothing to judge by)
            return ""
        inertia = inertia + model.dissipation.damping * dt
        ratio = self.kd * dt / inertia
        bad = [j for j in range(model.dof) if ratio[j] > 2.0]
        if not bad:
            return ""
        unit = {True: ("N·m·s/rad", "kg·m²"), False: ("N·s/m", "kg")}
        each = "; ".join(f"{model.joint_names[j]}: kd {self.kd[j]:g} {unit[bool(model.revolute[j])][0]} against "
                         f"{inertia[j]:.2g} {unit[bool(model.revolute[j])][1]} (kd·dt/I = {ratio[j]:.3g}; at most "
                         f"{2 * inertia[j] / dt:.3g})" for j in bad)
        return (f"controller.kd: more damping than a {dt * 1000:g}-ms period can apply to the joint's inertia — it "
                f"rings and trips the speed limit: {each}; lower kd there (and kp with it), or gains: auto")

    @staticmethod
    def _gains(value: float | list[float], n: int, name: str) -> np.ndarray:
        g = np.full(n, float(value)) if isinstance(value, (int, float)) else np.asarray(value, dtype=float)
        if g.shape != (n,):
            raise SettingError(name, f"has {g.size} values; the robot has {n} joints")
        if np.any(g < 0):
            raise SettingError(name, "must be >= 0")
        return g

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        tau = self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
        if self.auto:
            M = pin.crba(self._model, self._data, q)  # the upper triangle: mirror it (its rotors' armature in it)
            tau = (np.triu(M) + np.triu(M, 1).T) @ tau + self.kp_own * (q_ref - q)
        if self._inverse_dynamics:  # the rigid bodies', their rotors', and what the joints lose on the way
            tau += pin.rnea(self._model, self._data, q, qd_ref, qdd_ref)
            if self._damping is not None:
                tau += self._damping * qd_ref
            if self._friction is not None:
                tau += self._friction[0] * np.tanh(qd_ref / self._friction[1])
        elif self._gravity:
            tau += self._gravity_torque(q)
        return tau


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("joint-pd", config=JointPDConfig, factory=JointPD)
