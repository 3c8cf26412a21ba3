"""What a policy sees and what it is paid, from a run's own record (:class:`~rehabkit.core.results.metrics.Trace`) and
reference: the observation at a step, the reward terms over a policy period (vectorised over its rows)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from rehabkit.core.kinds.interfaces import EmbodiedPatient
from rehabkit.core.run.session import RunSession
from rehabkit.core.setup.errors import PluginSetupError
from rehabkit.learning.section import ObservationSpec
from rehabkit.models.hand_force import HandForce
from rehabkit.rehab.outcomes import interaction_forces

JERK_SCALE = 1e-6  # squared joint jerk [(rad/s³)²] is large: its term is counted in millionths


class Observer:
    """The observation terms of ``spec`` at a control step."""

    def __init__(self, spec: ObservationSpec, session: RunSession):
        self.spec, a = spec, session.setup
        self.a, self.trace = a, session.trace
        self.ref_q, self.ref_qd, _ = session.ref.views()
        self.goal_at = session.ref.goal_at
        self.dof = a.robot.model.dof
        self.ref_space = a.space
        self.hand_force = HandForce(a.robot.model) if a.patient is not None else None
        self.sizes = {"joint_state": 2 * self.dof, "reference": 2 * self.ref_q.shape[1],
                      "tracking_error": self.ref_q.shape[1], "goal": self.goal_at.shape[1], "phase": 1,
                      "interaction_force": 1, "person_torque": self.dof,
                      "person_state": len(a.patient.state()) if a.patient is not None else 0}
        if "person_state" in spec.terms and not self.sizes["person_state"]:
            raise PluginSetupError(a.loaded.source, ("learning", "observation", "terms"),
                                   "learning.observation.terms: person_state needs a simulated person with an inner "
                                   "state (patient.model)")

    def space(self) -> gym.Space:
        spec = self.spec
        boxes = {t: gym.spaces.Box(-np.inf, np.inf, (self.sizes[t],), np.float32) for t in spec.terms if t != "pixels"}
        if "phase" in boxes:
            boxes["phase"] = gym.spaces.Box(0.0, 1.0, (1,), np.float32)
        if spec.layout == "box":
            n = sum(b.shape[0] for b in boxes.values())
            low = np.concatenate([b.low for b in boxes.values()]).astype(np.float32)
            high = np.concatenate([b.high for b in boxes.values()]).astype(np.float32)
            return gym.spaces.Box(low, high, (n,), np.float32)
        if "pixels" in spec.terms:
            boxes["pixels"] = gym.spaces.Box(0, 255, (spec.height, spec.width, 3), np.uint8)
        return gym.spaces.Dict({t: boxes[t] for t in spec.terms})

    def observe(self, k: int) -> Any:
        a, n = self.a, self.a.schedule.steps
        _, q, qd = a.backend.state()
        row = min(k, n - 1)
        out: dict[str, np.ndarray] = {}
        for term in self.spec.terms:
            if term == "joint_state":
                value = np.concatenate([q, qd])
            elif term == "reference":
                value = np.concatenate([self.ref_q[row], self.ref_qd[row]])
            elif term == "tracking_error":
                value = self.ref_q[row] - self.ref_space.point(q)  # (in the reference's space: joints, or the hand)
            elif term == "goal":
                value = self.goal_at[row]
            elif term == "phase":  # (as the policy controller computes it: t over the episode's length)
                value = np.array([min(1.0, k * a.schedule.control_dt / a.sc.duration)])
            elif term == "interaction_force":
                value = np.array([self._force(max(0, k - 1), q)])
            elif term == "person_state":
                value = a.patient.state()
            elif term == "person_torque":
                tau_h = self.trace.tau_h
                value = tau_h[max(0, k - 1)] if tau_h is not None else np.zeros(self.dof)
            else:  # pixels
                spec = self.spec
                out[term] = a.backend.render(spec.camera, spec.width, spec.height)
                continue
            out[term] = np.asarray(value, np.float32)
        if self.spec.layout == "box":
            return np.concatenate([out[t] for t in self.spec.terms]).astype(np.float32)
        return out

    def _force(self, row: int, q: np.ndarray) -> float:
        trace = self.trace
        if trace.f_h is not None:
            return float(trace.f_h[row])
        if trace.tau_h is None or self.hand_force is None:
            return 0.0
        return float(np.linalg.norm(self.hand_force(q, trace.tau_h[row])))


class RewardTerms:
    """The weighted reward terms over the control steps [k0, k1) of a policy period."""

    def __init__(self, weights: dict[str, float], session: RunSession, every: int):
        self.weights, a = weights, session.setup
        self.a, self.trace, self.goal_at = a, session.trace, session.ref.goal_at
        self.dt = a.schedule.control_dt
        self.period = every * self.dt
        self.hand_force = HandForce(a.robot.model) if a.patient is not None and session.trace.f_h is None else None
        self.tolerance = a.sc.outcomes.tolerance_m
        self.ref_space = a.space
        self.embodied = isinstance(a.patient, EmbodiedPatient)

    def terms(self, k0: int, k1: int) -> dict[str, float]:
        if k1 <= k0:
            return {name: 0.0 for name in self.weights}
        tr, rows = self.trace, slice(k0, k1)
        out = {}
        for name, weight in self.weights.items():
            out[name] = weight * self.period * getattr(self, f"_{name}")(tr, rows, k0, k1)
        return out

    def _tracking(self, tr, rows, k0, k1) -> float:
        err = self.ref_space.planned(tr)[rows] - self.ref_space.points(tr.q[rows])
        return -float(np.mean(np.sum(err**2, axis=1)))

    def _interaction_force(self, tr, rows, k0, k1) -> float:
        if tr.f_h is not None:
            return -float(np.mean(tr.f_h[rows]))
        if tr.tau_h is None or self.hand_force is None:
            return 0.0
        force = interaction_forces(self.hand_force.jacobians(tr.q[rows]), tr.tau_h[rows])
        return -float(np.mean(np.linalg.norm(force, axis=1)))

    def _assistance(self, tr, rows, k0, k1) -> float:
        beyond = tr.tau[rows] - self.a.robot.gravity_torques(tr.q[rows])
        return -float(np.mean(np.sum(beyond**2, axis=1)))

    def _jerk(self, tr, rows, k0, k1) -> float:
        start = max(0, k0 - 2)  # two rows before: the period's first jerks
        qd = tr.qd[start:k1]
        if len(qd) < 3:
            return 0.0
        jerk = np.diff(qd, n=2, axis=0) / self.dt**2
        return -JERK_SCALE * float(np.mean(np.sum(jerk**2, axis=1)))

    def _reached(self, tr, rows, k0, k1) -> float:
        hand, goal = self.a.robot.fk(tr.q[k1 - 1])[:3, 3], self.ref_space.hand(self.goal_at[k1 - 1])
        return 1.0 / self.period if np.linalg.norm(hand - goal) < self.tolerance else 0.0

