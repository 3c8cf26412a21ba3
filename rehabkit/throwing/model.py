"""Underhand throws: a parametric wrist path, its retargeting to a robot, and the ball's flight.

A throw is a pendulum-like swing of the hand about the shoulder in a vertical plane
turned ``aim`` about the vertical: from hanging (φ = 0) back to ``back`` (rest), then
forward to ``release`` where it lets go with angular speed ``omega`` (a quintic that
starts at rest and ends at that speed with no acceleration), at distance ``radius``
from the shoulder. Retargeting (Mohammadi et al., Sec. III) keeps the timing and
scales the geometry by the ratio of arm lengths, so the release speed scales by the
same ratio and the flying direction is kept.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from rehabkit.models.time_laws import quintic

GRAVITY = 9.81
PARAMS = ("back", "release", "t_back", "t_fwd", "omega", "radius", "aim")  # angles [rad], times [s], [rad/s], [m]


@dataclass(frozen=True)
class Throw:
    """Throw parameters (see the module docstring)."""

    back: float
    release: float
    t_back: float
    t_fwd: float
    omega: float
    radius: float
    aim: float

    def vector(self) -> np.ndarray:
        return np.array([getattr(self, f.name) for f in fields(self)])

    @classmethod
    def from_vector(cls, v: np.ndarray) -> Throw:
        return cls(*(float(x) for x in v))

    def scaled(self, factor: float) -> Throw:
        """Retargeted to an arm ``factor`` times as long: same timing and angles, radius scaled."""
        return Throw(self.back, self.release, self.t_back, self.t_fwd, self.omega, self.radius * factor, self.aim)

    @property
    def release_time(self) -> float:
        return self.t_back + self.t_fwd


def _quintic(p0, p1, v1, T, t):
    """Position, velocity, acceleration of a quintic from rest at p0 to p1 with speed v1 and no acceleration."""
    # coefficients of p(s) = p0 + a3 s^3 + a4 s^4 + a5 s^5, s = t (rest and zero acceleration at the start)
    d, vT = p1 - p0, v1 * T
    a3 = (10 * d - 4 * vT) / T**3
    a4 = (-15 * d + 7 * vT) / T**4
    a5 = (6 * d - 3 * vT) / T**5
    p = p0 + a3 * t**3 + a4 * t**4 + a5 * t**5
    v = 3 * a3 * t**2 + 4 * a4 * t**3 + 5 * a5 * t**4
    a = 6 * a3 * t + 12 * a4 * t**2 + 20 * a5 * t**3
    return p, v, a


def swing_angle(th: Throw, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """φ, φ̇, φ̈ from the start of the back swing to the release."""
    t = np.asarray(t, float)
    back = t < th.t_back
    phi, dphi, ddphi = np.empty_like(t), np.empty_like(t), np.empty_like(t)
    phi[back], dphi[back], ddphi[back] = _rest_to_rest(0.0, th.back, th.t_back, t[back])
    tf = np.clip(t[~back] - th.t_back, 0.0, th.t_fwd)
    phi[~back], dphi[~back], ddphi[~back] = _quintic(th.back, th.release, th.omega, th.t_fwd, tf)
    return phi, dphi, ddphi


def _rest_to_rest(p0, p1, T, t):
    s, ds, dds = quintic(t / T)
    d = p1 - p0
    return p0 + d * s, d * ds / T, d * dds / T**2


def hand_path(th: Throw, shoulder: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hand position, velocity, acceleration (N×3) about ``shoulder``; x forward, z up."""
    return on_arc(th, shoulder, *swing_angle(th, t))


def follow_through(th: Throw, shoulder: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """After the release the swing goes on along its arc, its speed fading to rest over ``t[-1]``."""
    T = float(t[-1]) if len(t) and t[-1] > 0 else 1.0
    u = np.clip(np.asarray(t, float) / T, 0.0, 1.0)
    s, ds, _ = quintic(u)
    ds = ds / T
    covered = u - (2.5 * u**4 - 3 * u**5 + u**6)  # ∫(1 − s) du
    return on_arc(th, shoulder, th.release + th.omega * T * covered, th.omega * (1 - s), -th.omega * ds)


def on_arc(th: Throw, shoulder: np.ndarray, phi, dphi, ddphi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations on the swing circle for an angle profile φ(t)."""
    fwd = np.array([np.cos(th.aim), np.sin(th.aim), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    r = th.radius
    sin, cos = np.sin(phi)[:, None], np.cos(phi)[:, None]
    p = shoulder + r * (sin * fwd + cos * down)
    tangent = cos * fwd - sin * down
    v = r * dphi[:, None] * tangent
    a = r * (ddphi[:, None] * tangent - (dphi**2)[:, None] * (sin * fwd + cos * down))
    return p, v, a


def plane_crossing(p0: np.ndarray, v0: np.ndarray, plane_x: float) -> tuple[np.ndarray, float] | None:
    """Where and when a ball thrown from p0 with v0 crosses the vertical plane x = plane_x (no drag)."""
    if v0[0] <= 1e-9 or plane_x <= p0[0]:
        return None
    t = (plane_x - p0[0]) / v0[0]
    return parabola(p0, v0, np.array([t]))[0], float(t)


def parabola(p0: np.ndarray, v0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Ballistic positions (N×3) at times ``t`` after release."""
    t = np.asarray(t, float)[:, None]
    return p0 + v0 * t + 0.5 * np.array([0.0, 0.0, -GRAVITY]) * t**2
