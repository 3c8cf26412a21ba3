"""Force-limiting reactions: what the robot does when the interaction force passes its limit, when the scenario asks
for more than a stop (``safety.reactions``).

A stop and a stiff hold is the reaction that hurts when the force comes from the person (a spasm, a push against
the exoskeleton): the robot holds its posture and the force keeps rising. Rehabilitation robots limit such a force
by giving way (Bessler et al. 2021 frame the skill as limiting the force; admittance and impedance control do it):

- **yield**: the robot becomes compliant — gravity and the joints' friction compensated, damped, no stiffness
  toward the old posture — so the person's force moves it; each joint's damping is what holds it to
  ``yield_speed_deg_s`` (a prismatic joint: ``yield_speed_m_s``) under the force at its limit, pushing where it
  acts in the worst direction (Jᵀ at the trip). A soft wall ``wall_deg`` (``wall_m``) inside each joint's range
  stops a joint arriving at the speed bound within the wall's width; beyond the range (and its margin) the position
  rule stops the robot, and faster than ``max_speed_deg_s`` (``max_speed_m_s``) the velocity rule does, each in its
  own stop category. Suits a person who must not be resisted (spasticity, a patient pushing out of a posture): the
  force stays at what moving the damped arm takes.
- **retreat**: the robot moves away along the force — its reference runs in the direction the force would move the
  joints (M⁻¹ Jᵀ F), the fastest joint at ``retreat_speed_deg_s`` (``retreat_speed_m_s``) — until the force is
  below ``release_n``, then holds there (the hold gains), and retreats again if the force passes its limit again; at
  a soft wall it cannot go further and stops. Suits a pinch or a squeeze the robot itself caused (moving into the
  person or an obstacle): it gives back the space it took.

Both keep every other rule of the envelope: the layer still checks the state each control step. A joint too light for
the damping a yield needs at the control rate (damping · dt above half its inertia: a small wrist) is held where it was
instead, and every hold's gains are kept within what a control period can apply stably to the joint's inertia.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from rehabkit.core.safety.stopping import joint_inertia, mass_matrix, stable_gains
from rehabkit.core.scenario.safety import ForceReaction

SPEED_GRACE_S = 0.1  # how fast the allowance for the robot's own speed at the trip decays (time constant)


def per_kind(revolute: np.ndarray, degrees: float, metres: float) -> np.ndarray:
    """A setting per joint in SI: ``degrees`` (as radians) for a revolute joint, ``metres`` for a prismatic one."""
    return np.where(revolute, math.radians(degrees), metres)


class Compliance:
    """A force-limiting reaction under way (``yield`` or ``retreat``), from the trip at ``t0`` in state ``q0``.

    ``lo``, ``hi``: the joint ranges the layer keeps to [rad]; ``inertia``: the joint-space inertia at the trip
    (None: no dynamic model, the hold gains stand in); ``gravity(q)``, ``friction``: what is compensated;
    ``joint_torque(q, force)``: the torques the interaction force exerts on the joints (retreat only)."""

    def __init__(self, reaction: ForceReaction, limit_n: float, t0: float, q0: np.ndarray, lo: np.ndarray,
                 hi: np.ndarray, revolute: np.ndarray, effort: np.ndarray, inertia: np.ndarray | None,
                 gravity: Callable[[np.ndarray], np.ndarray] | None, friction: np.ndarray | None,
                 hold_kp: float, hold_kd: float,
                 joint_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None,
                 qd0: np.ndarray | None = None,
                 push_torque: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None = None,
                 dt: float = 1e-3, joint_mass: np.ndarray | None = None):
        self.kind, self.limit = reaction.type, limit_n
        self.release = reaction.release_n if reaction.release_n is not None else 0.6 * limit_n
        r = reaction  # (each joint's own: a revolute joint's from degrees, a prismatic joint's in metres)
        self.vmax = per_kind(revolute, r.max_speed_deg_s, r.max_speed_m_s)
        self.vretreat = per_kind(revolute, r.retreat_speed_deg_s, r.retreat_speed_m_s)
        span = hi - lo
        # (a joint without limits, a continuous one, has no wall)
        wall = np.where(np.isfinite(span), np.minimum(per_kind(revolute, r.wall_deg, r.wall_m), span / 4), 0.0)
        self.wall_lo, self.wall_hi = lo + wall, hi - wall
        mass = joint_mass if joint_mass is not None else (
            np.diag(inertia) if inertia is not None else np.full(len(q0), hold_kd * 0.1))
        self.inertia = inertia
        # the torque per newton each joint can get from the force (the norm of its row of Jᵀ), at the trip
        reach = None
        if joint_torque is not None:
            rows = [joint_torque(q0, axis) for axis in np.eye(3)]
            if all(r is not None for r in rows):
                reach = np.linalg.norm(np.array(rows), axis=0)
        if reach is not None:
            damping = np.maximum(reach * limit_n / per_kind(revolute, r.yield_speed_deg_s, r.yield_speed_m_s),
                                 mass / 0.1)
        else:  # where the force acts is unknown: a tenth of a second to damp a joint's own motion
            damping = mass / 0.1
        # damping applied once a control period keeps a joint's motion decaying only up to ~m/2dt; a joint that would
        # need more (a light wrist: the force at its limit would spin it past the bound) is held where it was
        # instead, with the hold's gains, while the others give way
        self.held = damping > 0.5 * mass / dt
        self.damping = np.where(self.held, 0.0, damping)
        # a joint arriving at the speed bound stops within the wall's width: ½ m v² = ½ k w²
        self.wall_k = np.where(wall > 0, mass * (self.vmax / np.where(wall > 0, wall, 1.0)) ** 2, 0.0)
        self.wall_d = 2.0 * np.sqrt(self.wall_k * mass)
        self.gravity, self.friction, self.effort = gravity, friction, effort
        # the hold's gains, within what a control period can apply stably to each joint's inertia
        self.hold_kp, self.hold_kd = stable_gains(hold_kp, hold_kd, mass, dt)
        self.push_torque = push_torque or joint_torque
        self.q_ref = np.clip(q0, self.wall_lo, self.wall_hi)
        self.qd_ref = np.zeros(len(q0))
        self.moving = self.kind == "retreat"  # retreating (else holding where it went)
        self.blocked_at: float | None = None  # a retreat that reached a soft wall with the force still high
        self._last_t = self.t0 = t0
        # the robot's own speed at the trip (a fast passive stretch that met a spastic catch) is damped out, not a
        # breach of the bound: the bound allows it, decaying over SPEED_GRACE_S
        self.v0 = np.nan_to_num(qd0) if qd0 is not None else np.zeros(len(q0))
        self.force = 0.0

    @classmethod
    def start(cls, reaction: ForceReaction, limit_n: float, t: float, q: np.ndarray, robot, lo: np.ndarray,
              hi: np.ndarray, gravity, config, joint_torque=None, qd: np.ndarray | None = None,
              push_torque=None, dt: float = 1e-3) -> Compliance:
        """The reaction from the trip at ``t`` in posture ``q`` of ``robot`` (its model: inertia, friction, effort
        limits, joint kinds), with the layer's ranges, gravity and hold gains (``config``: the envelope)."""
        friction = None
        try:
            f = np.asarray(robot.pin_model.friction, float)[: robot.dof]
            friction = f if np.any(f) else None
        except Exception:  # noqa: BLE001 (no dynamic model: nothing known to compensate)
            pass
        return cls(reaction, limit_n, t, np.asarray(q, float), lo, hi, robot.revolute, robot.limits.effort,
                   mass_matrix(robot, q), gravity, friction, config.hold_kp, config.hold_kd, joint_torque, qd,
                   push_torque, dt, joint_inertia(robot, q))

    def broken(self, t: float, q: np.ndarray, qd: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               vmax: np.ndarray) -> tuple | None:
        """A rule the reaction keeps, broken now: ``(rule, joint index, value, limit, why)``; None while all hold.
        ``vmax``: the run's speed limits, which a held joint keeps (the reaction's bound is for those giving way)."""
        bad = ~(np.isfinite(q) & np.isfinite(qd))
        if bad.any():
            return "non-finite", int(np.argmax(bad)), None, None, "a non-finite state"
        outside = (q < lo) | (q > hi)
        if outside.any():
            j = int(np.argmax(outside))
            return "position", j, float(q[j]), float(lo[j] if q[j] < lo[j] else hi[j]), "a joint beyond its range"
        carried = np.abs(self.v0) * math.exp(-(t - self.t0) / SPEED_GRACE_S)
        bound = np.where(self.held, vmax, np.maximum(self.vmax, carried))
        over = np.abs(qd) > bound
        if over.any():
            j = int(np.argmax(over))
            return "velocity", j, float(qd[j]), float(bound[j]), f"a joint faster than the {self.kind}'s bound"
        if self.blocked_at is not None:
            return "interaction-force", None, self.force, self.limit, "the force above its limit at a soft wall"
        return None

    def observe(self, t: float, q: np.ndarray, force: np.ndarray) -> None:
        """The interaction force now (what the retreat follows and releases on); a retreat's reference moves on."""
        self.force = float(np.linalg.norm(force))
        if self.kind != "retreat":
            return
        if self.moving and self.force <= self.release:
            self.moving = False
        elif not self.moving and self.force > self.limit:
            self.moving = True
        # the speed the robot had at the trip, carried on and decaying (stopping it at once would press the person)
        speed = self.v0 * math.exp(-(t - self.t0) / SPEED_GRACE_S)
        if self.moving:
            speed = speed + self._away(q, force)
        dt = max(t - self._last_t, 0.0)
        ref = np.clip(self.q_ref + speed * dt, self.wall_lo, self.wall_hi)
        if self.moving and dt > 0 and self.force > self.limit and np.allclose(ref, self.q_ref, atol=1e-12, rtol=0.0):
            self.blocked_at = self.blocked_at if self.blocked_at is not None else t
        self.q_ref, self.qd_ref, self._last_t = ref, speed, t

    def _away(self, q: np.ndarray, force: np.ndarray) -> np.ndarray:
        """The retreat's joint speeds: along M⁻¹ Jᵀ F, the fastest joint at its retreat speed (zero where the
        force's direction in the joints is unknown)."""
        tau_f = self.push_torque(q, force) if self.push_torque is not None else None
        if tau_f is None or not np.all(np.isfinite(tau_f)):
            return np.zeros_like(q)
        direction = np.linalg.solve(self.inertia, tau_f) if self.inertia is not None else tau_f
        scale = np.max(np.abs(direction) / self.vretreat)
        return direction / scale if scale > 0 else np.zeros_like(q)

    def torque(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """What to send now: compliant (yield), or following the retreat's reference; within the effort limits."""
        if self.kind == "yield":  # damped toward the speed it had, decaying: braking at once would press the person
            tau = -self.damping * (qd - self.v0 * math.exp(-(t - self.t0) / SPEED_GRACE_S))
            below, above = q < self.wall_lo, q > self.wall_hi
            if below.any() or above.any():
                push = np.where(below, self.wall_lo - q, 0.0) + np.where(above, self.wall_hi - q, 0.0)
                tau += np.where(below | above, self.wall_k * push - self.wall_d * qd, 0.0)
            if self.friction is not None:
                tau += self.friction * np.tanh(qd / 0.02)  # Coulomb friction, smoothed near rest
            if self.held.any():
                tau = np.where(self.held, self.hold_kp * (self.q_ref - q) - self.hold_kd * qd, tau)
        else:
            tau = self.hold_kp * (self.q_ref - q) + self.hold_kd * (self.qd_ref - qd)
        if self.gravity is not None:
            tau += self.gravity(q)
        return np.clip(tau, -self.effort, self.effort)
