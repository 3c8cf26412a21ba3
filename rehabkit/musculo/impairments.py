"""The time-varying parts of an impaired arm, one small state machine each, stepped once per control period.

- :class:`StretchReflex` — spasticity: a muscle stretched faster than a threshold (in optimal fibre lengths per
  second) is excited in proportion to the excess, one reflex delay later (Lance's velocity-dependent resistance;
  what a Tardieu test finds as a catch at high speed and none at low speed).
- :class:`Tremor` — a narrow-band torque: a damped complex oscillator at the tremor frequency driven by noise,
  its real part scaled to the set RMS amplitude (a Lorentzian band of the set width around that frequency).
- :class:`MuscleFatigue` — each muscle's capacity c (a fraction of its force) falls with its activation and
  recovers at rest: dc/dt = −r_f a c + r_r (1 − c)(1 − a).
"""

from __future__ import annotations

import cmath
import hashlib
import math

import numpy as np


class NoiseStream:
    """Standard normal numbers drawn in blocks from ``rng`` (a call per control step would cost more than the
    draw), with a digest of everything drawn: a replay shows it gave the person the same noise."""

    def __init__(self, rng: np.random.Generator, block: int = 16384):
        self.rng, self.block = rng, block
        self.values, self.next = np.empty(0), 0
        self.digest = hashlib.sha256()

    def normal(self, k: int) -> np.ndarray:
        if self.next + k > len(self.values):
            self.values, self.next = self.rng.standard_normal(max(self.block, k)), 0
            self.digest.update(self.values.tobytes())
        out = self.values[self.next : self.next + k]
        self.next += k
        return out


class StretchReflex:
    """Extra excitation e = gain · max(0, v(t − delay)/L₀ − threshold) per muscle."""

    def __init__(self, gain: np.ndarray, threshold_l0_s: np.ndarray, delay_s: float, l0: np.ndarray, dt: float):
        self.gain, self.threshold, self.l0 = np.asarray(gain, float), np.asarray(threshold_l0_s, float), l0
        self.ring = np.zeros((max(1, round(delay_s / dt)), len(l0)))  # past lengthening speeds [L0/s]
        self.k = 0
        self.active = bool(np.any(self.gain > 0))

    def excitation(self, lengthening_m_s: np.ndarray) -> np.ndarray:
        """The reflex's excitation now, given the muscles' lengthening speeds [m/s] now."""
        slot = self.k % len(self.ring)
        late = self.ring[slot].copy()  # one delay ago
        self.ring[slot] = lengthening_m_s / self.l0
        self.k += 1
        return self.gain * np.maximum(0.0, late - self.threshold)


class Tremor:
    """RMS ``amplitude`` [N·m] per joint in a band of ``bandwidth_hz`` around ``frequency_hz``."""

    def __init__(self, amplitude: np.ndarray, frequency_hz: float, bandwidth_hz: float, dt: float,
                 noise: NoiseStream):
        self.amplitude = np.asarray(amplitude, float)
        decay = math.exp(-math.pi * bandwidth_hz * dt)
        self.pole = decay * cmath.exp(2j * math.pi * frequency_hz * dt)
        self.drive = math.sqrt(1.0 - decay**2)  # so that E|z|² = 2, E[Re z]² = 1
        self.z = np.zeros(len(self.amplitude), complex)
        self.noise = noise
        self.active = bool(np.any(self.amplitude > 0))

    def torque(self) -> np.ndarray:
        n = len(self.z)
        w = self.noise.normal(2 * n)
        w = w[:n] + 1j * w[n:]
        self.z = self.pole * self.z + self.drive * w
        return self.amplitude * self.z.real


class MuscleFatigue:
    """Capacity per muscle, a fraction of its unfatigued force."""

    def __init__(self, n: int, rate_per_s: float, recovery_per_s: float, dt: float):
        self.capacity = np.ones(n)
        self.rate, self.recovery, self.dt = rate_per_s, recovery_per_s, dt
        self.active = rate_per_s > 0

    def step(self, activation: np.ndarray) -> np.ndarray:
        c = self.capacity
        c += self.dt * (-self.rate * activation * c + self.recovery * (1.0 - c) * (1.0 - activation))
        np.clip(c, 0.0, 1.0, out=c)
        return c
