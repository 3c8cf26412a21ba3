"""What the robot's own dynamics say about the task's first plan, before it runs (``rehabkit validate``): the torque
each joint needs to follow it — its bodies, rotors, declared damping and friction — against the joint's effort
limit, and joints the model gives next to no inertia (a file whose links declare none), which a controller scaled by
the inertia (``gains: auto``) cannot hold."""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.robot import Robot

SAMPLES = 200  # points along the plan at which the torque is taken
NEAR_LIMIT = 0.9  # a joint needing more than this share of its effort limit is said (feedback needs some room)
TINY_INERTIA = 1e-6  # [kg·m², kg]: a joint lighter than this as its own torque meets it has no inertia to speak of


def _own_dynamics(robot: Robot) -> bool:
    """The robot's dynamics are Pinocchio's model of its file (not a plugin's own, such as a parallel mechanism's)."""
    kind = type(robot)
    return kind.inverse_dynamics is Robot.inverse_dynamics and kind.gravity_torque is Robot.gravity_torque


def plan_torque(robot: Robot, trajectory, within: float | None = None) -> list[str]:
    """Each joint whose torque along ``trajectory`` (its first ``within`` seconds, where only they run) comes within
    10 % of its effort limit or beyond: how much, when, and the fix."""
    if not _own_dynamics(robot):
        return []
    model = robot.model
    span = float(trajectory.duration) if within is None else min(float(trajectory.duration), within)
    t = np.linspace(0.0, span, SAMPLES)
    q, qd, qdd = trajectory.sample(t)
    try:
        tau = np.array([robot.inverse_dynamics(q[i], qd[i], qdd[i]) for i in range(len(t))])
    except Exception:  # noqa: BLE001 (a model Pinocchio can't do dynamics on: nothing to say here)
        return []
    share = np.abs(tau) / model.limits.effort
    said = []
    for j in np.flatnonzero(share.max(axis=0) > NEAR_LIMIT):
        k = int(np.argmax(share[:, j]))
        unit = "N·m" if model.revolute[j] else "N"
        over = "over" if share[k, j] > 1 else "within 10 % of"
        still = abs(float(robot.gravity_torque(q[k])[j]))  # (what holding that posture alone takes)
        limit = model.limits.effort[j]
        if still > limit:
            fix = (f"holding that posture alone takes {still:.4g} {unit}: a posture the joint cannot hold against "
                   "gravity (other targets, or a higher limit if the drive has it)")
        elif still > NEAR_LIMIT * limit:
            fix = (f"holding that posture alone takes {still:.4g} {unit} ({still / limit:.0%} of the limit): little is "
                   "left to move it with (other targets, or a higher limit if the drive has it)")
        else:
            fix = "a slower plan: longer segment durations"
        said.append(f"{model.joint_names[j]}: the first plan needs {tau[k, j]:+.4g} {unit} at t={t[k]:.2f} "
                    f"s, {over} its {limit:g} {unit} effort limit ({share[k, j]:.0%}): its torque will be clipped and "
                    f"it will lag; {fix}")
    return said


def missing_inertia(robot: Robot, q: np.ndarray) -> list[str]:
    """Joints the model gives next to no inertia at ``q`` (1/(M⁻¹)ⱼⱼ, rotor included): their links declare none."""
    if not _own_dynamics(robot):
        return []
    from rehabkit.core.safety.stopping import joint_inertia

    try:
        inertia = joint_inertia(robot.model, np.asarray(q, float))
    except Exception:  # noqa: BLE001 (a singular model: Pinocchio's own error says more at the run)
        return []
    if inertia is None:
        return []
    model = robot.model
    return [f"{model.joint_names[j]}: the model gives it {inertia[j]:.2g} {'kg·m²' if model.revolute[j] else 'kg'} "
            "of inertia (the links it moves declare next to none in the file, and no rotor inertia, armature): a "
            "controller scaled by the inertia (joint-pd gains: auto) has no stiffness there; give the file its "
            "links' inertials, or manual gains" for j in np.flatnonzero(inertia < TINY_INERTIA)]
