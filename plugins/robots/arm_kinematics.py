"""Closed-form inverse kinematics of the MANUS/ARM arm (the 6 revolute joints).

The modified-DH table (see ``arm.py``) is PUMA-like: joints 4–6 meet at the wrist
centre, so the first three joints place the wrist centre and the last three orient
the gripper. In the frame turned by q1 the wrist centre sits at (u, d3, v) with

    u = a2·cos q2 + d4·sin(q2 + q3),   v = −a2·sin q2 + d4·cos(q2 + q3)

which gives q1 (two shoulder branches), q3 from u² + v² = a2² + d4² + 2·a2·d4·sin q3
(two elbow branches) and q2 as a planar two-link angle. The wrist rotation
R36 = R03ᵀ·R06 has third column (sin q5 cos q4, −cos q5, sin q4 sin q5) and
second row (sin q5 cos q6, −sin q5 sin q6, ·), giving the two wrist branches.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

A2, D3, D4 = 0.3967, 0.0992, 0.3234  # [m], from the MANUS table
SINGULAR = 1e-9
# (compiled: the keypad's Cartesian jog solves this up to three times a control step, where numpy's per-call cost on
# 3×3 matrices and single angles is many times the arithmetic)


@njit(cache=True, nogil=True)
def wrist_centre_joints(w):  # pragma: no cover - compiled
    """(q1, q2, q3) placing the wrist centre at ``w`` (arm frame): up to four branches, the rows of a (k, 3) array
    (one shoulder branch where the two coincide, one elbow branch where those do)."""
    x, y, v = w[0], w[1], w[2]
    out = np.empty((4, 3))
    k = 0
    r2 = x * x + y * y
    if r2 < D3**2 - 1e-12:
        return out[:0]  # inside the cylinder swept by the shoulder offset
    root = math.sqrt(max(r2 - D3**2, 0.0))
    for iu in range(1 if root == 0.0 else 2):  # (one branch when the root is zero)
        u = root if iu == 0 else -root
        q1 = math.atan2(y, x) - math.atan2(D3, u)
        s3 = (u**2 + v**2 - A2**2 - D4**2) / (2 * A2 * D4)
        if abs(s3) > 1 + 1e-12:
            continue
        s3 = min(1.0, max(-1.0, s3))
        up = math.asin(s3)
        for i3 in range(1 if up == math.pi - up else 2):
            q3 = up if i3 == 0 else math.pi - up
            phi = q3 - math.pi / 2  # forearm angle relative to the upper arm, in the arm's plane
            q2 = math.atan2(-v, u) - math.atan2(D4 * math.sin(phi), A2 + D4 * math.cos(phi))
            out[k, 0], out[k, 1], out[k, 2] = q1, q2, q3
            k += 1
    return out[:k]


@njit(cache=True, nogil=True)
def wrist_joints(r36, q4_hint=0.0):  # pragma: no cover - compiled
    """(q4, q5, q6) giving the wrist rotation ``r36``: two branches, one at the q5 = 0 singularity; rows of a
    (k, 3) array."""
    c5 = min(1.0, max(-1.0, -r36[1, 2]))
    s5 = math.sqrt(max(1.0 - c5**2, 0.0))
    if s5 < SINGULAR:  # q4 and q6 turn about the same axis: keep q4, give the rest to q6
        c4, s4 = math.cos(q4_hint), math.sin(q4_hint)
        # the first row of the remaining rotation of rows 5 and 6: R4ᵀ r36, R4 the MDH row 4 (α3 = +90°) at q4
        m00, m01 = c4 * r36[0, 0] + s4 * r36[2, 0], c4 * r36[0, 1] + s4 * r36[2, 1]
        out = np.empty((1, 3))
        out[0, 0], out[0, 1] = q4_hint, 0.0 if c5 > 0 else math.pi
        out[0, 2] = math.atan2(-m01, m00) if c5 > 0 else math.atan2(m01, -m00)
        return out
    out = np.empty((2, 3))
    for k in range(2):
        s = s5 if k == 0 else -s5
        out[k, 0] = math.atan2(r36[2, 2] / s, r36[0, 2] / s)
        out[k, 1] = math.atan2(s, c5)
        out[k, 2] = math.atan2(-r36[1, 1] / s, r36[1, 0] / s)
    return out


@njit(cache=True, nogil=True)
def elbow_up(q1, q2, q3):  # pragma: no cover - compiled
    """Whether the elbow sits above the shoulder–wrist line (the ARM controller's choice)."""
    s2, c2, s23, c23 = math.sin(q2), math.cos(q2), math.sin(q2 + q3), math.cos(q2 + q3)
    elbow_v = -A2 * s2
    wrist_u, wrist_v = A2 * c2 + D4 * s23, -A2 * s2 + D4 * c23
    elbow_u = A2 * c2
    # height of the shoulder–wrist line under the elbow (the line may be vertical: compare across it)
    cross = wrist_u * elbow_v - wrist_v * elbow_u
    return cross > 0 if wrist_u >= 0 else cross < 0


@njit(cache=True, nogil=True)
def _wrap(a):  # pragma: no cover - compiled
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True, nogil=True)
def _solutions(wrist_pose, elbow_up_only):  # pragma: no cover - compiled
    """:func:`arm_ik`'s solutions as the rows of a (k, 6) array."""
    centres = wrist_centre_joints(wrist_pose[:3, 3])
    out = np.empty((2 * len(centres), 6))
    k = 0
    for c in range(len(centres)):
        q1, q2, q3 = centres[c, 0], centres[c, 1], centres[c, 2]
        if elbow_up_only and not elbow_up(q1, q2, q3):
            continue
        c1, s1, c23, s23 = math.cos(q1), math.sin(q1), math.cos(q2 + q3), math.sin(q2 + q3)
        r03 = np.empty((3, 3))  # rotation of frame 3 (MDH rows 1–3: α = 0, −90°, 0)
        r03[0, 0], r03[0, 1], r03[0, 2] = c1 * c23, -c1 * s23, -s1
        r03[1, 0], r03[1, 1], r03[1, 2] = s1 * c23, -s1 * s23, c1
        r03[2, 0], r03[2, 1], r03[2, 2] = -s23, -c23, 0.0
        r36 = np.zeros((3, 3))  # R03ᵀ R06
        for i in range(3):
            for j in range(3):
                for m in range(3):
                    r36[i, j] += r03[m, i] * wrist_pose[m, j]
        wrists = wrist_joints(r36)
        for w in range(len(wrists)):
            out[k, 0], out[k, 1], out[k, 2] = _wrap(q1), _wrap(q2), _wrap(q3)
            out[k, 3], out[k, 4], out[k, 5] = _wrap(wrists[w, 0]), _wrap(wrists[w, 1]), _wrap(wrists[w, 2])
            k += 1
    return out[:k]


def arm_ik(wrist_pose: np.ndarray, elbow_up_only: bool = False) -> list[np.ndarray]:
    """All 6-joint solutions placing frame 6 at ``wrist_pose`` (4x4, arm frame), angles in (−π, π]; with
    ``elbow_up_only`` those of the elbow-up branches (the wrist is not solved for the others)."""
    return list(_solutions(np.ascontiguousarray(wrist_pose, dtype=float), elbow_up_only))


@njit(cache=True, nogil=True)
def nearest_elbow_up(pose, gripper, lift, reference, arm, lower, upper):  # pragma: no cover - compiled
    """Elbow-up solutions (rows of q) placing the gripper tip, ``gripper`` along the last axis of frame 6, at ``pose``
    (the arm's base frame, raised by the ``lift``), nearest ``reference`` (its largest joint difference) first, ties
    in branch order. The six arm joints start at index ``arm`` of q; each angle is the turn nearest the reference's
    within [lower, upper] (branches without one are left out), the other joints keep the reference's values."""
    wrist = pose.copy()
    for i in range(3):
        wrist[i, 3] -= wrist[i, 2] * gripper + (lift if i == 2 else 0.0)
    sols = _solutions(wrist, True)
    two_pi = 2 * np.pi
    out, far = np.empty((len(sols), len(reference))), np.empty(len(sols))
    k = 0
    for b in range(len(sols)):
        ok, worst = True, 0.0
        for j in range(len(reference)):
            out[k, j] = reference[j]
        for j in range(arm, arm + 6):
            a, lo, hi = sols[b, j - arm], lower[j], upper[j]
            a = a + two_pi * np.rint((reference[j] - a) / two_pi)  # the turn nearest the reference
            a = a - two_pi if a > hi else (a + two_pi if a < lo else a)
            ok = ok and lo - 1e-12 <= a <= hi + 1e-12
            out[k, j] = min(max(a, lo), hi)
            worst = max(worst, abs(out[k, j] - reference[j]))
        if not ok:
            continue
        i = k  # (insertion behind its equals: nearest first, ties in branch order)
        while i > 0 and far[i - 1] > worst:
            i -= 1
        for m in range(k, i, -1):  # (element by element: numba takes seconds to compile row assignments)
            far[m] = far[m - 1]
            for j in range(len(reference)):
                out[m, j], out[m - 1, j] = out[m - 1, j], out[m, j]
        far[i] = worst
        k += 1
    return out[:k]
