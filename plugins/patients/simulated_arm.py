"""A simulated patient's arm in the exoskeleton: the torques a person applies at the robot's joints.

Per joint, the person's torque is the sum of

- passive tissue: a spring toward a rest posture and a damper, τ_p = −K (q − q_rest) − B q̇;
- spastic resistance: a velocity-dependent stretch reflex, τ_s = −G · sign(q̇) · max(0, |q̇(t − d_r)| − v_th),
  from the velocity a reflex delay d_r ago (resistance grows with speed above a threshold);
- voluntary effort toward the movement's goal as the person perceives it (``delay_s`` ago): a hand
  force F = K_v (x_goal − x) − D_v ẋ capped at the person's force, τ_v = Jᵀ F (or the joint-space
  form for joint-space tasks), capped at each joint's strength, not pushing a joint further out of
  its active range, weaker along the motion the faster the joint goes (none at ``speed_deg_s``),
  scaled by the remaining capacity and by signal-dependent noise (a band-limited Gaussian process
  whose deviation is a fraction of the effort). The person goes for the goal at
  their own pace, not along the robot's path: a stiff robot holds them back, a compliant one lets
  them do the work;
- end-range stiffness: toward either end of the joint's passive range the tissue stiffens, τ_e = −T e^{(q − q_hi)/w}
  + T e^{(q_lo − q)/w} (T at the end itself, e-fold per w degrees): the end-feel that bounds the passive range;
- fatigue: the capacity falls with effort and recovers at rest, dc/dt = −r_f e + r_r (1 − c), with e
  the effort as a fraction of strength, so repetitions wear the person out.

Everything random comes from the plugin's own stream of the scenario seed, so a replay with another
controller gives the person the same noise.
"""

from __future__ import annotations

import hashlib
import math
from typing import Annotated

import numpy as np
import pinocchio as pin
from numba import njit
from pydantic import Field

from rehabkit.plugin import Context, JointRom, Metric, Patient, SettingError, StrictModel, hookimpl

PerJoint = float | list[float]
NonNegative = Annotated[float, Field(ge=0)]  # (a bound on each branch of a union: JSON Schema has no 'ge' on a union)
SERIES_EVERY = 10  # control steps between logged samples of the person's state
# rows of SimulatedArm.joint (per-joint parameters) and entries of SimulatedArm.const, as the compiled step reads them
K, B, REST, PASSIVE_LO, PASSIVE_HI, GAIN_S, V_TH, STRENGTH, ACTIVE_LO, ACTIVE_HI, INV_STRENGTH = range(11)
END_T, END_W, STIFF, DAMP, HAND_F, SPEED, NOISE_A, NOISE_B, NOISE = range(9)


class Spasticity(StrictModel):
    """Velocity-dependent stretch reflex."""

    gain_nms_rad: PerJoint = Field(0.0, description="resistance per rad/s above the threshold [N·m·s/rad]")
    threshold_deg_s: NonNegative | list[NonNegative] = Field(30.0, description="reflex threshold speed")
    reflex_delay_s: float = Field(0.03, ge=0, le=0.2, description="reflex loop delay")


class Voluntary(StrictModel):
    """The person's own effort toward the cue."""

    strength_nm: PerJoint = Field(5.0, description="largest voluntary torque per joint [N·m]")
    hand_force_n: float = Field(20.0, gt=0, description="largest voluntary hand force (Cartesian cues) [N]")
    stiffness: float = Field(300.0, ge=0, description="effort per distance to the goal: N/m (hand) or N·m/rad")
    damping: float = Field(20.0, ge=0, description="effort against the own speed: N·s/m or N·m·s/rad")
    delay_s: float = Field(0.2, ge=0, le=1.0, description="reaction delay: a new goal is perceived this late")
    noise: float = Field(0.15, ge=0, description="signal-dependent noise, deviation as a fraction of the effort")
    noise_hz: float = Field(4.0, gt=0, description="bandwidth of the noise process")
    participation: float = Field(1.0, ge=0, le=1, description="how much of their capacity the person uses")
    speed_deg_s: float = Field(90.0, gt=0, description="the fastest the person moves a joint: their effort along the "
                                                       "motion falls to none at this speed (force-velocity)")


class Fatigue(StrictModel):
    """Capacity lost with effort and regained at rest."""

    rate_per_s: float = Field(0.02, ge=0, description="capacity lost per second at full effort")
    recovery_per_s: float = Field(0.005, ge=0, description="share of the lost capacity regained per second")


class EndRange(StrictModel):
    """The tissue's stiffening toward the ends of the passive range (the end-feel a therapist feels)."""

    torque_nm: float = Field(2.0, ge=0, description="resistance at either end of the passive range [N·m]")
    width_deg: float = Field(2.0, gt=0, description="how sharply it rises: e-fold per this many degrees")


class SimulatedArmConfig(StrictModel):
    """A person's arm: passive tissue, spasticity, voluntary effort and fatigue (parameters per joint or one)."""

    stiffness_nm_rad: PerJoint = Field(2.0, description="passive stiffness [N·m/rad]")
    damping_nms_rad: PerJoint = Field(0.3, description="passive damping [N·m·s/rad]")
    rest_deg: list[float] | None = Field(None, description="rest posture (default: where the arm is at the start)")
    spasticity: Spasticity = Spasticity()
    voluntary: Voluntary = Voluntary()
    fatigue: Fatigue = Fatigue()
    end_range: EndRange = EndRange()
    rom: dict[str, JointRom] | None = Field(None, description="the simulated person's own ranges per joint (default: "
                                                              "the profile's): what an assessment measures")


def _per_joint(value: PerJoint, n: int, name: str) -> np.ndarray:
    v = np.full(n, float(value)) if isinstance(value, (int, float)) else np.asarray(value, float)
    if v.shape != (n,) or np.any(v < 0):
        raise SettingError(tuple(name.split(".")), f"needs one value or {n} values, all >= 0")
    return v


class SimulatedArm(Patient):
    """Passive tissue + delayed stretch reflex + noisy, fatiguing voluntary effort; see the module docstring."""

    relaxed = {"voluntary": {"participation": 0.0}}
    metrics = (Metric("patient_capacity_final", outcome=True, description="voluntary capacity left at the end"),
               Metric("patient_voluntary_work_j", "J", outcome=True, description="the person's positive work"))

    def __init__(self, config: SimulatedArmConfig, context: Context):
        model = context.robot.model
        n, dt = model.dof, context.control_dt
        self.n, self.dt = n, dt
        k = _per_joint(config.stiffness_nm_rad, n, "stiffness_nm_rad")
        b = _per_joint(config.damping_nms_rad, n, "damping_nms_rad")
        sp, vol, fat = config.spasticity, config.voluntary, config.fatigue
        g_s = _per_joint(sp.gain_nms_rad, n, "spasticity.gain_nms_rad")
        v_th = np.radians(_per_joint(sp.threshold_deg_s, n, "spasticity.threshold_deg_s"))
        strength = _per_joint(vol.strength_nm, n, "voluntary.strength_nm")
        if not np.all(strength > 0):
            raise SettingError(("voluntary", "strength_nm"), "must be > 0")
        self.vol, self.fat = vol, fat
        self.delay_s = vol.delay_s
        lim = model.limits  # the effective limits: the profile's passive range is in them
        lo, hi = lim.lower.copy(), lim.upper.copy()
        profile = context.patient
        own = config.rom if config.rom is not None else (profile.joints if profile is not None else {})
        unknown = [name for name in own if name not in model.joint_names]
        if unknown:
            raise SettingError("rom", f"no joint(s) {unknown} on robot '{model.name}' "
                             f"(its joints: {', '.join(model.joint_names)})")
        passive_lo, passive_hi = np.full(n, -np.inf), np.full(n, np.inf)
        for j, name in enumerate(model.joint_names):
            rom = own.get(name)
            if rom is not None:
                passive_lo[j], passive_hi[j] = np.radians(rom.passive_deg)
                if rom.active_deg is not None:
                    lo[j], hi[j] = np.radians(rom.active_deg)
        self.rest: np.ndarray | None = None  # None: the posture of the first step (the person sits relaxed)
        if config.rest_deg is not None:
            if len(config.rest_deg) != n:
                raise SettingError("rest_deg", f"needs {n} values")
            self.rest = np.radians(config.rest_deg)
        self.cartesian = context.reference_space == "cartesian"
        if self.cartesian:
            self.pin_model = model.pin_model
            self.data = self.pin_model.createData()
            self.frame = model.ee_frame_id
        self._no_hand = np.zeros((6, n)), np.zeros(3)  # (joint-space cues: the compiled step's unused arguments)
        self.rng = context.stream("patient")
        noise_a = math.exp(-2 * math.pi * vol.noise_hz * dt)
        self.joint = np.array([k, b, np.zeros(n) if self.rest is None else self.rest, passive_lo, passive_hi, g_s,
                               v_th, strength, lo, hi, 1.0 / strength])
        self.const = np.array([config.end_range.torque_nm, np.radians(config.end_range.width_deg), vol.stiffness,
                               vol.damping, vol.hand_force_n, math.radians(vol.speed_deg_s), noise_a,
                               math.sqrt(1 - noise_a**2), vol.noise])
        self.noise_state = self.rng.standard_normal(n)
        self._draws = np.empty((0, n))
        self._digest = hashlib.sha256(self.noise_state.tobytes())
        self._next = 0
        self.reflex = np.zeros((max(1, round(sp.reflex_delay_s / dt)), n))  # ring buffer of past velocities
        self.step = 0
        self.capacity = 1.0
        self.voluntary_work = 0.0
        self._log_t: list[float] = []
        self._log: list[tuple[float, float, float]] = []

    def _white(self) -> np.ndarray:
        if self._next >= len(self._draws):  # drawn in blocks: one call per step would cost more than the model
            self._draws, self._next = self.rng.standard_normal((4096, self.n)), 0
            self._digest.update(self._draws.tobytes())
        w = self._draws[self._next]
        self._next += 1
        return w

    def torque(self, t, q, qd, goal):
        if self.rest is None:
            self.rest = q.copy()
            self.joint[REST] = q
        if self.cartesian:
            J = pin.computeFrameJacobian(self.pin_model, self.data, q, self.frame, pin.LOCAL_WORLD_ALIGNED)
            x = self.data.oMf[self.frame].translation
        else:
            J, x = self._no_hand
        drive = self.capacity * self.vol.participation
        tau, load, work, size2 = _person_torque(q, qd, goal, J, x, self.cartesian, self.joint, self.const,
                                                self.reflex, self.step % len(self.reflex), self.noise_state,
                                                self._white(), drive)
        fat = self.fat
        self.capacity += self.dt * (-fat.rate_per_s * load + fat.recovery_per_s * (1.0 - self.capacity))
        self.capacity = min(1.0, max(0.0, self.capacity))
        self.voluntary_work += max(0.0, work) * self.dt
        if self.step % SERIES_EVERY == 0:
            self._log_t.append(t)
            self._log.append((self.capacity, math.sqrt(size2), load))
        self.step += 1
        return tau

    def state(self) -> np.ndarray:
        """The remaining voluntary capacity (fatigue)."""
        return np.array([self.capacity])

    def run_metrics(self, trace) -> dict[str, float]:
        return {"patient_capacity_final": self.capacity, "patient_voluntary_work_j": self.voluntary_work}

    def inputs(self) -> dict[str, str]:
        return {"patient_noise": self._digest.hexdigest()[:16]}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        t, v = np.asarray(self._log_t), np.asarray(self._log).reshape(-1, 3)
        return {"patient/capacity": (t, v[:, 0]), "patient/voluntary_torque_nm": (t, v[:, 1]),
                "patient/effort_fraction": (t, v[:, 2])}


@njit(cache=True, nogil=True)
def _person_torque(q, qd, goal, J, x, cartesian, p, c, reflex, slot, noise_state, white, drive):  # pragma: no cover
    """One control step of the module docstring's model, compiled (numpy's per-call dispatch on a handful of joints
    costs more than the model): the torques, and the effort's load (its mean share of strength), power (effort · q̇)
    and squared size. ``p``, ``c``: the per-joint and scalar parameters (rows and entries named above); the velocity
    ring ``reflex`` (its row ``slot``) and the noise process are advanced in place."""
    n = len(q)
    tau, effort = np.empty(n), np.empty(n)
    end_t, w = c[END_T], c[END_W]
    for j in range(n):
        t = -p[K, j] * (q[j] - p[REST, j]) - p[B, j] * qd[j]
        if end_t:  # (bounded exponents: a joint driven far past its end must not overflow)
            t -= end_t * math.exp(min((q[j] - p[PASSIVE_HI, j]) / w, 30.0))
            t += end_t * math.exp(min((p[PASSIVE_LO, j] - q[j]) / w, 30.0))
        late = reflex[slot, j]  # the velocity one reflex delay ago
        reflex[slot, j] = qd[j]
        tau[j] = t - p[GAIN_S, j] * np.sign(late) * max(0.0, abs(late) - p[V_TH, j])
    if cartesian:  # a hand force toward the goal, capped at the person's, through Jᵀ
        force = np.empty(3)
        for i in range(3):
            v = 0.0
            for j in range(n):
                v += J[i, j] * qd[j]
            force[i] = c[STIFF] * (goal[i] - x[i]) - c[DAMP] * v
        size = math.sqrt(force[0] * force[0] + force[1] * force[1] + force[2] * force[2])
        if size > c[HAND_F]:
            force *= c[HAND_F] / size
        for j in range(n):
            effort[j] = J[0, j] * force[0] + J[1, j] * force[1] + J[2, j] * force[2]
    else:
        for j in range(n):
            target = min(max(goal[j], p[ACTIVE_LO, j]), p[ACTIVE_HI, j])
            effort[j] = c[STIFF] * (target - q[j]) - c[DAMP] * qd[j]
    load = work = size2 = 0.0
    for j in range(n):
        e = min(max(effort[j], -p[STRENGTH, j]), p[STRENGTH, j])
        # no voluntary push further out of the active range, nor faster than the person moves
        if (q[j] >= p[ACTIVE_HI, j] and e > 0) or (q[j] <= p[ACTIVE_LO, j] and e < 0):
            e = 0.0
        if e * qd[j] > 0:  # force-velocity: pushing along the motion, less the faster it goes (none at v_max)
            e *= max(0.0, 1.0 - abs(qd[j]) / c[SPEED])
        noise_state[j] = c[NOISE_A] * noise_state[j] + c[NOISE_B] * white[j]
        e *= drive * (1.0 + c[NOISE] * noise_state[j])
        tau[j] += e
        load += abs(e) * p[INV_STRENGTH, j]
        work += e * qd[j]
        size2 += e * e
    return tau, load / n, work, size2


@hookimpl
def rehabkit_register_patients(registry) -> None:
    registry.add("simulated-arm", config=SimulatedArmConfig, factory=SimulatedArm)
