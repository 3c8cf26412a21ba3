"""Outcome measures against signals whose answers are known."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.signal import butter, filtfilt

from rehabkit.rehab.outcomes import (
    assistance_ratio,
    interaction_forces,
    path_length_ratio,
    range_of_motion,
    sparc,
    time_to_target,
)

FS = 1000.0


def min_jerk_speed(duration: float, fs: float = FS, amplitude: float = 1.0) -> np.ndarray:
    s = np.arange(0.0, duration + 0.5 / fs, 1.0 / fs) / duration
    return amplitude * 30 * s**2 * (1 - s) ** 2 / duration


def sparc_from_continuous_spectrum(fc: float = 10.0, threshold: float = 0.05) -> float:
    """SPARC of the minimum-jerk speed profile from its continuous Fourier transform (quadrature, no FFT).

    64-point Gauss–Legendre: exact to rounding for this integrand (a quartic times at most ten cycles of the
    exponential), as scipy's adaptive quad is to 2e-15 at every frequency here, in 1/40 of the time."""
    v = lambda s: 30 * s**2 * (1 - s) ** 2  # noqa: E731 (unit duration)
    nodes, weights = np.polynomial.legendre.leggauss(64)
    s, w = (nodes + 1) / 2, weights / 2  # on [0, 1]
    f = np.linspace(0.0, fc, 4001)
    m = np.abs(np.exp(-2j * np.pi * f[:, None] * s[None]) @ (w * v(s)))
    assert abs(m[1000] - np.hypot(quad(lambda x: v(x) * np.cos(2 * np.pi * f[1000] * x), 0, 1)[0],
                                  quad(lambda x: v(x) * np.sin(2 * np.pi * f[1000] * x), 0, 1)[0])) < 1e-12
    m /= m.max()
    keep = np.flatnonzero(m >= threshold)
    f, m = f[keep[0] : keep[-1] + 1], m[keep[0] : keep[-1] + 1]
    return float(-np.sum(np.hypot(np.diff(f) / (f[-1] - f[0]), np.diff(m))))


def test_sparc_of_minimum_jerk_matches_its_continuous_spectrum():
    expected = sparc_from_continuous_spectrum()
    assert -1.45 < expected < -1.35  # the published value for a minimum-jerk reach is about -1.4
    assert sparc(min_jerk_speed(1.0), FS) == pytest.approx(expected, abs=0.01)


def test_sparc_is_invariant_to_amplitude_and_duration():
    base = sparc(min_jerk_speed(1.0), FS)
    assert sparc(min_jerk_speed(1.0, amplitude=7.0), FS) == pytest.approx(base, abs=1e-9)
    # a movement twice as long has its spectrum compressed by two: the same arc once normalised
    assert sparc(min_jerk_speed(2.0), FS) == pytest.approx(base, abs=0.01)


def test_sparc_penalises_noise_and_submovements():
    smooth = min_jerk_speed(1.0)
    rng = np.random.default_rng(3)
    # speed noise in the band of human movement (low-passed at 8 Hz), 20 % of the peak speed
    b, a = butter(2, 8.0 / (FS / 2))
    jitter = filtfilt(b, a, rng.normal(size=smooth.size))
    noisy = np.clip(smooth + 0.2 * smooth.max() * jitter / jitter.std(), 0, None)
    two = np.concatenate([smooth[:-1], smooth])  # two sub-movements, a stop between
    assert sparc(noisy, FS) < sparc(smooth, FS) - 0.3
    assert sparc(two, FS) < sparc(smooth, FS) - 0.5
    # white noise above 10 Hz is outside SPARC's band: the cut-off keeps it from counting
    assert sparc(smooth + rng.normal(0, 1e-3, smooth.size), FS) == pytest.approx(sparc(smooth, FS), abs=0.02)


def test_path_length_ratio_of_a_line_and_a_semicircle():
    line = np.linspace([0, 0, 0], [0.3, 0.1, 0], 200)
    assert path_length_ratio(line) == pytest.approx(1.0, abs=1e-12)
    a = np.linspace(0, np.pi, 2001)
    semicircle = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) * 0.2
    assert path_length_ratio(semicircle) == pytest.approx(np.pi / 2, rel=1e-6)


def test_time_to_target_of_an_exponential_approach():
    t = np.arange(0, 3, 1e-3)
    tau, tol = 0.2, 0.01
    x = np.column_stack([np.exp(-t / tau), np.zeros_like(t), np.zeros_like(t)])
    assert time_to_target(t, x, np.zeros(3), tol) == pytest.approx(tau * np.log(1 / tol), abs=2e-3)
    assert time_to_target(t, x, np.zeros(3), tol, dwell=0.5) == pytest.approx(tau * np.log(1 / tol), abs=2e-3)
    assert np.isnan(time_to_target(t, x + 1, np.zeros(3), tol))


def test_time_to_target_needs_the_dwell():
    t = np.arange(0, 3, 1e-3)
    x = np.zeros((t.size, 3))
    x[:, 0] = 0.1
    x[500:550, 0] = 0.0  # passes through for 50 ms
    x[2000:, 0] = 0.0  # then arrives for good at 2 s
    assert time_to_target(t, x, np.zeros(3), 0.01) == pytest.approx(0.5)
    assert time_to_target(t, x, np.zeros(3), 0.01, dwell=0.2) == pytest.approx(2.0)


def test_range_of_motion():
    q = np.column_stack([np.sin(np.linspace(0, 2 * np.pi, 500)), np.full(500, 0.3)])
    assert range_of_motion(q) == pytest.approx([2.0, 0.0], abs=1e-4)


def test_assistance_ratio_counts_positive_work():
    n, dt = 1000, 1e-3
    qd = np.ones((n, 2))
    robot = np.full((n, 2), 3.0)
    person = np.full((n, 2), 1.0)
    assert assistance_ratio(robot, person, qd, dt) == pytest.approx(0.75)
    # a person braking the motion does negative work: all the positive work is the robot's
    assert assistance_ratio(robot, -person, qd, dt) == pytest.approx(1.0)
    assert assistance_ratio(np.zeros((n, 2)), person, qd, dt) == pytest.approx(0.0)


def test_interaction_force_recovers_the_hand_force():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(20, 3, 4))
    F = rng.normal(size=(20, 3)) * 30
    tau = np.einsum("nij,ni->nj", J, F)  # τ = Jᵀ F
    got = interaction_forces(J, tau)
    well = np.linalg.svd(J, compute_uv=False)[:, -1] > 0.3  # (damped least squares: within 0.5 % there)
    assert well.sum() > 10 and np.allclose(got[well], F[well], rtol=5e-3, atol=0.02 * 30)
    # a straight arm: torques its cuffs carry stay a finite hand force (plain least squares: unbounded)
    straight = np.array([[[0.0, 0.0, 0.0, 0.0], [0.6, 0.3, 1e-6, 0.0], [0.0, 0.0, 0.0, 1e-6]]])
    assert np.abs(interaction_forces(straight, np.array([[0.0, 0.0, 1.0, 1.0]]))).max() < 1.0  # (plain: 1e6 N)
