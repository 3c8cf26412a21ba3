"""Clinical outcome measures of a movement, from sampled signals.

Each function takes plain arrays so it can be checked against signals with
known answers (``tests/test_outcomes.py``) and reused on recorded data.

- :func:`sparc`: spectral arc length of the speed profile (Balasubramanian et al.,
  2015): the arc length of the normalised Fourier magnitude spectrum up to an
  adaptive cut-off; closer to zero is smoother. Invariant to the movement's
  amplitude and duration.
- :func:`path_length_ratio`: travelled path over the straight line (1 = straight).
- :func:`time_to_target`: first time the point comes within a tolerance of a
  target and stays there for a dwell time.
- :func:`range_of_motion`: per-joint excursion.
- :func:`assistance_ratio`: the robot's share of the positive mechanical work done
  on the limb.
- :func:`interaction_forces`: the hand force equivalent to the person's joint torques.
"""

from __future__ import annotations

import numpy as np

from rehabkit.models.hand_force import hand_forces


def sparc(speed: np.ndarray, fs: float, pad_level: int = 4, fc: float = 10.0, amp_threshold: float = 0.05) -> float:
    """Spectral arc length of a speed profile (SPARC, Balasubramanian et al. 2015).

    Args:
        speed: Speed magnitude samples [any unit] of one movement.
        fs: Sampling rate [Hz].
        pad_level: Zero padding: the FFT has ``2**(ceil(log2 n) + pad_level)`` points.
        fc: Largest cut-off frequency [Hz].
        amp_threshold: The spectrum is cut where it last exceeds this fraction of its peak (below ``fc``).

    Returns:
        A negative number; a minimum-jerk reach gives about -1.6, tremor or sub-movements make it smaller.
    """
    v = np.asarray(speed, float)
    if v.size < 2 or not np.any(v):
        return float("nan")
    nfft = int(2 ** (np.ceil(np.log2(v.size)) + pad_level))
    mag = np.abs(np.fft.rfft(v, nfft))
    freq = np.fft.rfftfreq(nfft, 1.0 / fs)
    mag = mag / mag.max()
    keep = freq <= fc
    freq, mag = freq[keep], mag[keep]
    above = np.flatnonzero(mag >= amp_threshold)
    freq, mag = freq[above[0] : above[-1] + 1], mag[above[0] : above[-1] + 1]
    if freq.size < 2:
        return 0.0
    df = np.diff(freq) / (freq[-1] - freq[0])
    return float(-np.sum(np.hypot(df, np.diff(mag))))


def path_length(points: np.ndarray) -> float:
    """Length of a sampled path (N, d)."""
    p = np.asarray(points, float)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


def path_length_ratio(points: np.ndarray, start: np.ndarray | None = None, end: np.ndarray | None = None) -> float:
    """Travelled length over the straight distance from ``start`` to ``end`` (default: the path's ends)."""
    p = np.asarray(points, float)
    a = p[0] if start is None else np.asarray(start, float)
    b = p[-1] if end is None else np.asarray(end, float)
    straight = float(np.linalg.norm(b - a))
    return path_length(p) / straight if straight > 0 else float("nan")


def time_to_target(t: np.ndarray, points: np.ndarray, target: np.ndarray, tolerance: float,
                   dwell: float = 0.0) -> float:
    """Time from ``t[0]`` until the point comes within ``tolerance`` of ``target`` and stays ``dwell`` seconds
    (NaN if it never does; at the end of the samples a shorter stay counts)."""
    t = np.asarray(t, float)
    inside = np.linalg.norm(np.asarray(points, float) - np.asarray(target, float), axis=1) <= tolerance
    if not inside.any():
        return float("nan")
    # the step each sample's run of 'inside' ends at: entries whose run lasts the dwell qualify
    change = np.flatnonzero(np.diff(inside.astype(np.int8)))
    starts = np.concatenate([[0], change + 1])
    ends = np.concatenate([change + 1, [len(inside)]])
    for a, b in zip(starts, ends):
        if inside[a] and (t[b - 1] - t[a] >= dwell - 1e-12 or b == len(inside)):
            return float(t[a] - t[0])
    return float("nan")


def range_of_motion(q: np.ndarray) -> np.ndarray:
    """Per-joint excursion max − min over the samples (N, dof) → (dof,)."""
    q = np.asarray(q, float)
    return q.max(axis=0) - q.min(axis=0) if len(q) else np.zeros(q.shape[1:])


def positive_work(tau: np.ndarray, qd: np.ndarray, dt: float) -> float:
    """Positive mechanical work of joint torques (N, dof) over velocities (N, dof) [J]."""
    power = np.einsum("ij,ij->i", np.asarray(tau, float), np.asarray(qd, float))
    return float(np.clip(power, 0.0, None).sum() * dt)


def assistance_ratio(tau_robot: np.ndarray, tau_person: np.ndarray, qd: np.ndarray, dt: float) -> float:
    """The robot's positive work over the robot's and the person's together (0 = all patient, 1 = all robot)."""
    w_r, w_p = positive_work(tau_robot, qd, dt), positive_work(tau_person, qd, dt)
    return w_r / (w_r + w_p) if w_r + w_p > 0 else float("nan")


def interaction_forces(jacobians: np.ndarray, tau_person: np.ndarray) -> np.ndarray:
    """Hand forces F (N, 3) with Jᵀ F = τ in the (damped) least-squares sense, from position Jacobians (N, 3, dof)
    (:func:`rehabkit.models.hand_force.hand_forces`).

    The least-squares force is the part of the person's torques that acts through the
    hand; torques in the arm's null space (e.g. about the elbow swivel) have no hand force.
    """
    J = np.asarray(jacobians, float)
    if not len(J):
        return np.zeros((0, 3))
    return hand_forces(J, tau_person)
