"""A learned policy as a controller: a policy file (:mod:`rehabkit.models.policy`, saved by a training on
``rehabkit.gym``) run at its own rate inside any scenario — in simulation and over a robot link, exactly as any
controller, its torque through the safety layer.

It sees what it saw in training, from what a controller is given each step: ``joint_state`` (q, q̇), ``reference``
(the planner's reference and its rate), ``tracking_error`` (reference − q, or − the hand's position for Cartesian
references), ``phase`` (time over the trained episode's length). Its action, held between its steps, is a
residual added to the controller it was trained on (built from the file, or ``base``), or the whole torque over
the robot's gravity compensation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from rehabkit.control import Policy
from rehabkit.kinematics import FilePath
from rehabkit.plugin import Context, Controller, SettingError, StrictModel, hookimpl

CONTROLLER_TERMS = ("joint_state", "reference", "tracking_error", "phase")


class PolicyConfig(StrictModel):
    """The policy file and, for a residual policy, the controller it acts on."""

    file: FilePath = Field(description="the policy (.npz) a training saved, relative to the scenario")
    base: dict[str, Any] | None = Field(None, description="the controller a residual acts on (type and settings; "
                                                           "default: the one it was trained on, kept in the file)")


class PolicyController(Controller):
    """A learned policy (a file from rehabkit.gym training) as a controller; see the module."""

    def __init__(self, config: PolicyConfig, context: Context):
        path = context.resolve(config.file)
        if not path.exists():
            raise SettingError("file", f"no policy file {path}")
        self.policy = policy = Policy.load(path)
        meta, dof = policy.meta, context.robot.model.dof
        terms = meta.get("terms", [])
        if unseen := [t for t in terms if t not in CONTROLLER_TERMS]:
            raise SettingError("file", f"the policy observes {', '.join(unseen)}, which a controller is not "
                               f"given; train it on {', '.join(CONTROLLER_TERMS)}")
        action = meta.get("action", {})
        self.terms, self.kind = terms, action.get("kind", "residual")
        self.tuned = action.get("parameters", {}) if self.kind == "parameters" else {}
        outputs = len(self.tuned) if self.tuned else dof
        if policy.sizes[-1] != outputs or meta.get("dof", dof) != dof:
            raise SettingError("file", f"the policy has {policy.sizes[-1]} outputs; this robot and action need "
                                       f"{outputs}")
        scale = np.asarray(action.get("scale", 0.2), float)
        self.scale = context.robot.model.limits.effort * scale
        self.every = max(1, round(1.0 / (meta.get("policy_hz", 1.0 / context.control_dt) * context.control_dt)))
        self.duration = float(meta.get("duration_s", 1.0))
        self.robot = context.robot
        self.base: Controller | None = None
        if self.kind in ("residual", "parameters"):
            spec = config.base or meta.get("base")
            if not spec:
                raise SettingError("base", "a residual policy needs the controller it acts on (none in the file)")
            self.base = _build(spec, context)
            self.reference = self.base.reference
            self.metrics = self.base.metrics  # what it reports, it reports for the policy's run
            if self.tuned:
                self.base.tune({})  # (refuses a controller that tunes nothing)
                self._lo, self._hi = (np.array([r[i] for r in self.tuned.values()], float) for i in (0, 1))
        else:  # the whole torque: it takes the references the planner gives
            self.reference = context.reference_space
        self._gravity = context.robot.gravity_torque
        self._u = np.zeros(dof)
        self._k = 0
        self.actions: list[np.ndarray] = []

    @property
    def joint_reference(self):
        return self.base.joint_reference if self.base is not None else None

    def run_metrics(self, trace):
        return self.base.run_metrics(trace) if self.base is not None else {}

    def series(self):
        return self.base.series() if self.base is not None else {}

    def observe(self, t, q, qd, q_ref, qd_ref) -> np.ndarray:
        """The policy's input, as the learning environment made it."""
        parts = []
        for term in self.terms:
            if term == "joint_state":
                parts += [q, qd]
            elif term == "reference":
                parts += [q_ref, qd_ref]
            elif term == "tracking_error":
                parts.append(q_ref - (self.robot.fk(q)[:3, 3] if len(q_ref) != len(q) else q))
            else:  # phase
                parts.append([min(1.0, t / self.duration)])
        return np.concatenate(parts).astype(np.float32)

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        if self._k % self.every == 0:  # the policy's step; its action held until the next
            action = self.policy(self.observe(t, q, qd, q_ref, qd_ref))
            if self.tuned:
                self.base.tune(dict(zip(self.tuned, self._lo + (action + 1.0) * (self._hi - self._lo) / 2)))
            else:
                self._u = self.scale * action
        self._k += 1
        if self.base is not None:
            return self.base.compute(t, q, qd, q_ref, qd_ref, qdd_ref) + self._u
        return self._gravity(q) + self._u


def _build(spec: dict[str, Any], context: Context) -> Controller:
    """The base controller from its section (type and settings), from the run's installed plugins."""
    if spec.get("type") == "policy":
        raise SettingError("base", "a policy cannot act on a policy")
    try:
        return context.build("controller", spec)
    except ValueError as exc:  # its settings, said under base
        raise SettingError("base", str(exc)) from None


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("policy", config=PolicyConfig, factory=PolicyController)
