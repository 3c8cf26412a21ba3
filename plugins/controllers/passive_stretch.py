"""The passive part of a range-of-motion assessment: a slow robot-driven stretch of one joint at a time, stopped
at the end-feel — where the joint's resistance stiffens beyond a threshold —, at a torque cap, or where the
interaction force (a cuff's) reaches a cap, whichever comes first; each end's angle is the passive range.

From the start posture, for each joint: out toward the robot's upper limit at ``speed_deg_s``, back, out toward
the lower limit, back; the other joints held. The joint follows a PD on the ramp (gains from its inertia) with
gravity compensation; the resistance is the PD's effort against the motion, its stiffness the slope of that effort
over the last ``window_deg`` of travel; the torque cap counts from what holding the limb took as the stretch began
(its weight). The person should be relaxed (no voluntary effort) and the speed low (below their stretch reflex's
threshold).

The stretch watches the interaction force rather than leave it to the safety envelope: going out it slows from half
the force cap on (to a fifth of its speed at the cap, where it ends), and coming back — where a relaxed limb's
tissues and weight, lifted back, can press the cuffs harder than the stretch did — it slows from half the run's force
limit on and waits at 90 % of it until the force has eased.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from pydantic import Field

from rehabkit.plugin import Context, Controller, Metric, SettingError, StrictModel, hookimpl

MARGIN_DEG = 1.0  # the stretch stops this short of the robot's own limit
EASE_S = 0.5  # the return reaches its speed over this long
EASE_FILTER_S = 0.05  # the force the speed eases on, low-passed with this time constant


class PassiveStretchConfig(StrictModel):
    """Which joints, how fast, and what counts as the end of the range."""

    joints: list[str] | None = Field(None, description="joints to stretch, in order (default: all)")
    speed_deg_s: float = Field(10.0, gt=0, le=30, description="stretch speed (below the person's reflex threshold)")
    return_speed_deg_s: float = Field(20.0, gt=0, description="speed back to the start posture")
    end_feel_nm_deg: float = Field(1.0, gt=0, description="the end of the range: resistance stiffer than this")
    max_torque_nm: float = Field(10.0, gt=0, description="the stretch never pushes harder than this beyond what "
                                                        "holding the limb took as it began")
    window_deg: float = Field(1.0, gt=0, description="travel over which the stiffness is measured")
    max_force_n: float | None = Field(None, gt=0, description="the stretch also ends when the interaction force (a "
                                      "cuff's, a sensor's) reaches this (default: 80 % of the run's force limit)")
    bandwidth_hz: float = Field(8.0, gt=0, description="each joint's tracking bandwidth: stiffness M ω², damping 2 M ω "
                                                       "from its inertia at the start (stable for light and heavy "
                                                       "joints alike)")
    pause_s: float = Field(0.5, ge=0, description="rest at the start posture between stretches")


class PassiveStretch(Controller):
    """Stretches each joint to its end-feel and back (see the module docstring); reports the angles reached."""

    reference = "own"
    metrics = (Metric("passive_rom_deg_*", "deg", outcome=True,
                      description="a joint's passive range end (lower_, upper_<joint>), where the stretch ended"),
               Metric("passive_stop_t_*", "s", description="when each stretch ended"),
               Metric("passive_start_t_*", "s", description="when each stretch began"),
               Metric("passive_stop_*", "count",
                      description="why each stretch ended: 0 end-feel, 1 torque cap, 2 the robot's own limit, "
                                  "3 force cap"))

    def __init__(self, config: PassiveStretchConfig, context: Context):
        model = context.robot.model
        names = config.joints or model.joint_names
        if unknown := [j for j in names if j not in model.joint_names]:
            raise SettingError("joints", f"no joint(s) {unknown} on robot '{model.name}'")
        self.c, self.dt, self.gravity = config, context.control_dt, context.robot.gravity_torque
        self._model = model.pin_model
        margin = np.radians(MARGIN_DEG)
        self.lo, self.hi = model.limits.lower + margin, model.limits.upper - margin
        self.names = model.joint_names
        # the moves: (joint, direction); each goes out until it ends, then back to the start
        self.moves = [(model.joint_names.index(j), d) for j in names for d in (1, -1)]
        self.force = context.interaction_force
        limits = [v for v in (getattr(context.safety, "interaction_force_n", None),
                              getattr(getattr(context.patient, "comfort", None), "max_interaction_force_n", None))
                  if v is not None]
        self.max_force = config.max_force_n or (0.8 * min(limits) if limits else None)
        self.limit_force = min(limits) if limits else None
        self.found: dict[str, float] = {}
        self.ended: dict[str, float] = {}
        self.q0: np.ndarray | None = None
        self.joint_reference = None
        self._move, self._phase, self._pause, self._t, self._baseline, self._back_s = 0, "out", 0.0, 0.0, 0.0, 0.0
        self._samples: list[tuple[float, float]] = []  # (angle, resistance) on the way out
        self._f_eased: float | None = None  # the low-passed force the speed eases on
        self._eased_at = -1.0

    @staticmethod
    def duration(q0: np.ndarray, lower: np.ndarray, upper: np.ndarray, joints: list[int], config) -> float:
        """How long stretching ``joints`` from ``q0`` can take at most [s] (out to the robot's limits and back)."""
        out = sum((upper[j] - q0[j]) + (q0[j] - lower[j]) for j in joints)
        speed, back = math.radians(config.speed_deg_s), math.radians(config.return_speed_deg_s)
        return out / speed + out / back + 2 * len(joints) * (config.pause_s + 0.5)

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        self._t = t
        if self.q0 is None:
            self.q0, self.joint_reference = q.copy(), q.copy()
            w = 2 * math.pi * self.c.bandwidth_hz
            inertia = np.diag(pin.crba(self._model, self._model.createData(), q))
            self.kp, self.kd = inertia * w * w, 2 * inertia * w
        r, v = self.joint_reference, np.zeros_like(q)
        if self._move < len(self.moves):
            j, d = self.moves[self._move]
            v[j] = self._advance(j, d, r, q)
        push = self.kp * (r - q)
        if self._move < len(self.moves) and self._phase == "out":
            self._feel(j, d, q, float(push[j]))
        return push + self.kd * (v - qd) + self.gravity(q)

    def _advance(self, j: int, d: int, r: np.ndarray, q: np.ndarray) -> float:
        """Move the reference one step; its speed."""
        if self._phase == "out":
            key = f"passive_start_t_{'upper' if d > 0 else 'lower'}_{self.names[j]}"
            self.found.setdefault(key, self._t)  # (when this stretch began)
            speed = math.radians(self.c.speed_deg_s) * self._ease_out()
            r[j] += d * speed * self.dt
            limit = self.hi[j] if d > 0 else self.lo[j]
            if d * (r[j] - limit) >= 0:
                r[j] = limit
                self._end(j, d, q[j], 2)
            return d * speed
        if self._phase == "back":  # (easing into the return: a sudden reversal jerks the limb and the cuffs)
            self._back_s += self.dt
            speed = math.radians(self.c.return_speed_deg_s) * min(1.0, self._back_s / EASE_S) * self._ease_back()
            step = -d * speed * self.dt
            if d * (r[j] + step - self.q0[j]) <= 0:
                r[j], self._phase, self._pause = self.q0[j], "pause", 0.0
                return 0.0
            r[j] += step
            return -d * speed
        self._pause += self.dt  # resting at the start posture
        if self._pause >= self.c.pause_s:
            self._move, self._phase, self._samples = self._move + 1, "out", []
        return 0.0

    def _force_n(self) -> float | None:
        """The interaction force the speed eases on, low-passed (EASE_FILTER_S): eased on the raw force, the speed
        and the force it makes feed each other within a control step — a 125 Hz oscillation on a MyoArm's strap."""
        f = self.force() if self.force is not None else None
        if f is None:
            return None
        size = math.sqrt(float(f @ f))
        if self._eased_at != self._t:
            a = self.dt / (EASE_FILTER_S + self.dt)
            self._f_eased = size if self._f_eased is None else self._f_eased + a * (size - self._f_eased)
            self._eased_at = self._t
        return self._f_eased

    def _ease_out(self) -> float:
        """The stretch's speed factor: 1 below half the force cap, down to 0.2 at the cap."""
        f = self._force_n()
        if f is None or self.max_force is None:
            return 1.0
        return min(1.0, max(0.2, 1.0 - 0.8 * (f - 0.5 * self.max_force) / (0.5 * self.max_force)))

    def _ease_back(self) -> float:
        """The return's speed factor: 1 below half the run's force limit, falling to 0 (waiting) at 90 % of it."""
        f = self._force_n()
        if f is None or self.max_force is None:
            return 1.0
        limit = self.limit_force if self.limit_force is not None else self.max_force / 0.8
        return min(1.0, max(0.0, (0.9 * limit - f) / (0.4 * limit)))

    def _feel(self, j: int, d: int, q: np.ndarray, push: float) -> None:
        """The resistance against the motion (the PD's static part: its damping part is the start's transient,
        not the tissue) and its stiffness over the last window of travel, from one window past the start."""
        resistance = d * push
        angle = float(q[j])
        if d * (angle - self.q0[j]) < math.radians(self.c.window_deg):
            self._baseline = resistance  # what holding the limb took as the stretch began (its weight, say)
            return
        if resistance - self._baseline >= self.c.max_torque_nm:
            self._end(j, d, angle, 1)
            return
        if self.max_force is not None and self.force is not None and (f := self.force()) is not None \
                and f @ f >= self.max_force**2:  # (the cuff pressing too hard: the range ends here for now)
            self._end(j, d, angle, 3)
            return
        self._samples.append((angle, resistance))
        window = math.radians(self.c.window_deg)
        first = self._samples[0]
        if d * (angle - first[0]) < window:
            return
        while len(self._samples) > 2 and d * (angle - self._samples[1][0]) >= window:
            self._samples.pop(0)  # keep one window of travel
        a0, r0 = self._samples[0]
        stiffness = (resistance - r0) / abs(math.degrees(angle - a0))
        if stiffness >= self.c.end_feel_nm_deg:  # measured over the window: where it was felt is the middle
            self._end(j, d, angle - d * window / 2, 0)

    def _end(self, j: int, d: int, angle: float, why: int) -> None:
        side = "upper" if d > 0 else "lower"
        self.found[f"passive_rom_deg_{side}_{self.names[j]}"] = math.degrees(angle)
        self.found[f"passive_stop_t_{side}_{self.names[j]}"] = self._t
        self.ended[f"passive_stop_{side}_{self.names[j]}"] = float(why)
        self._phase, self._back_s = "back", 0.0  # (from where the reference is: a jump back would jerk the limb)

    def run_metrics(self, trace) -> dict[str, float]:
        return {**self.found, **self.ended}


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("passive-stretch", config=PassiveStretchConfig, factory=PassiveStretch)
