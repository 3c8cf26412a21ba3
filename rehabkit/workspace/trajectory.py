"""Cartesian trajectories for workspace planners: a path timed by a trapezoidal speed
profile, and the blend that joins an old trajectory to a new one without a jump."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import make_interp_spline

from rehabkit.models.time_laws import quintic


def smooth_path(points: np.ndarray, step: float = 0.001) -> np.ndarray:
    """A C2 cubic spline through ``points`` (chord-length parametrised), resampled every ``step`` [m]."""
    pts = np.asarray(points, dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
    pts = pts[keep]
    if len(pts) < 2:
        return pts
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    spline = make_interp_spline(s, pts, k=min(3, len(pts) - 1), bc_type="natural" if len(pts) > 3 else None)
    dense = spline(np.linspace(0.0, s[-1], max(2, int(np.ceil(s[-1] / step * 4)) + 1)))
    return resample(dense, step)


def resample(polyline: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` [m] of arc length along a polyline (last point kept)."""
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 1e-12:
        return polyline[:1].copy()
    at = np.append(np.arange(0.0, s[-1], step), s[-1])
    return np.column_stack([np.interp(at, s, polyline[:, i]) for i in range(polyline.shape[1])])


def trapezoid(length: float, v_max: float, a_max: float) -> tuple[float, float, float]:
    """(accelerating time, cruise time, peak speed) of a rest-to-rest trapezoidal (or triangular) profile."""
    t_acc = v_max / a_max
    if a_max * t_acc * t_acc >= length:  # never reaches v_max: triangular
        t_acc = float(np.sqrt(length / a_max))
        return t_acc, 0.0, a_max * t_acc
    return t_acc, (length - a_max * t_acc * t_acc) / v_max, v_max


class TimedPath:
    """A polyline sampled densely along its arc, followed with a trapezoidal speed profile."""

    def __init__(self, points: np.ndarray, v_max: float, a_max: float):
        self.points = np.asarray(points, dtype=float)
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.s[-1])
        self.t_acc, self.t_cruise, self.v_peak = trapezoid(self.length, v_max, a_max) if self.length > 0 else (0, 0, 0)
        self.a = a_max
        self.duration = 2 * self.t_acc + self.t_cruise
        # unit tangents and their change per metre, at the samples (finite differences)
        if len(self.points) > 1:
            d1 = np.gradient(self.points, self.s, axis=0)
            self.tangent = d1 / np.maximum(np.linalg.norm(d1, axis=1, keepdims=True), 1e-12)
            self.curv = np.gradient(self.tangent, self.s, axis=0) if len(self.points) > 2 else np.zeros_like(d1)
        else:
            self.tangent = self.curv = np.zeros((1, 3))

    def _arc(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, ta, tc = self.a, self.t_acc, self.t_cruise
        t = np.clip(t, 0.0, self.duration)
        s, v, acc = np.empty_like(t), np.empty_like(t), np.empty_like(t)
        up, flat, down = t < ta, (t >= ta) & (t < ta + tc), t >= ta + tc
        s[up], v[up], acc[up] = 0.5 * a * t[up] ** 2, a * t[up], a
        s_a = 0.5 * a * ta * ta
        s[flat], v[flat], acc[flat] = s_a + self.v_peak * (t[flat] - ta), self.v_peak, 0.0
        td = self.duration - t[down]
        s[down], v[down], acc[down] = self.length - 0.5 * a * td**2, a * td, -a
        return np.clip(s, 0, self.length), v, acc

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self.length == 0:
            z = np.zeros((len(t), 3))
            return np.tile(self.points[0], (len(t), 1)), z, z
        s, v, acc = self._arc(t)
        x = np.column_stack([np.interp(s, self.s, self.points[:, i]) for i in range(3)])
        tan = np.column_stack([np.interp(s, self.s, self.tangent[:, i]) for i in range(3)])
        cur = np.column_stack([np.interp(s, self.s, self.curv[:, i]) for i in range(3)])
        xd = tan * v[:, None]
        xdd = tan * acc[:, None] + cur * (v**2)[:, None]
        rest = t >= self.duration
        xd[rest], xdd[rest] = 0.0, 0.0
        return x, xd, xdd


class Sequence:
    """Trajectories one after another (each rest-to-rest)."""

    def __init__(self, parts: list):
        self.parts = parts
        self.starts = np.concatenate([[0.0], np.cumsum([p.duration for p in parts])])
        self.duration = float(self.starts[-1])

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = [np.zeros((len(t), 3)) for _ in range(3)]
        which = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.parts) - 1)
        for i, part in enumerate(self.parts):
            sel = which == i
            if sel.any():
                for o, v in zip(out, part.sample(t[sel] - self.starts[i])):
                    o[sel] = v
        return tuple(out)




class Junction:
    """From an old trajectory (from time ``offset`` in it) gradually to a new one over ``blend`` seconds.

    x = (1 - w) x_old + w x_new with w a quintic smoothstep, so position,
    velocity and acceleration are continuous where the blend starts and ends.
    """

    def __init__(self, old, offset: float, new, blend: float):
        self.old, self.offset, self.new, self.blend = old, offset, new, blend
        self.duration = max(new.duration, blend)

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        xo, vo, ao = self.old.sample(t + self.offset)
        xn, vn, an = self.new.sample(t)
        w, wd, wdd = (a[:, None] for a in quintic(t / self.blend))
        wd, wdd = wd / self.blend, wdd / self.blend**2
        x = (1 - w) * xo + w * xn
        v = (1 - w) * vo + w * vn + wd * (xn - xo)
        a = (1 - w) * ao + w * an + 2 * wd * (vn - vo) + wdd * (xn - xo)
        return x, v, a
