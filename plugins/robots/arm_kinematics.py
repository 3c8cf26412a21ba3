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

A2, D3, D4 = 0.3967, 0.0992, 0.3234  # [m], from the MANUS table
SINGULAR = 1e-9
# (scalar math throughout: numpy's functions on single floats cost ~1 µs a call, and the keypad's Cartesian jog
# solves this every control step)


def _rot03(q1: float, q2: float, q3: float) -> np.ndarray:
    """Rotation of frame 3 (MDH rows 1–3: α = 0, −90°, 0)."""
    c1, s1, c23, s23 = math.cos(q1), math.sin(q1), math.cos(q2 + q3), math.sin(q2 + q3)
    return np.array([[c1 * c23, -c1 * s23, -s1],
                     [s1 * c23, -s1 * s23, c1],
                     [-s23, -c23, 0.0]])


def _rot36_to_r4(q4: float) -> np.ndarray:
    """Rotation of MDH row 4 (α3 = +90°) at q4."""
    c, s = math.cos(q4), math.sin(q4)
    return np.array([[c, -s, 0.0], [0.0, 0.0, -1.0], [s, c, 0.0]])


def wrist_centre_joints(w) -> list[tuple[float, float, float]]:
    """(q1, q2, q3) placing the wrist centre at ``w`` (arm frame): up to four branches."""
    x, y, v = float(w[0]), float(w[1]), float(w[2])
    r2 = x * x + y * y
    if r2 < D3**2 - 1e-12:
        return []  # inside the cylinder swept by the shoulder offset
    out = []
    root = math.sqrt(max(r2 - D3**2, 0.0))
    for u in dict.fromkeys((root, -root)):  # (one branch when the root is zero)
        q1 = math.atan2(y, x) - math.atan2(D3, u)
        s3 = (u**2 + v**2 - A2**2 - D4**2) / (2 * A2 * D4)
        if abs(s3) > 1 + 1e-12:
            continue
        s3 = min(1.0, max(-1.0, s3))
        for q3 in dict.fromkeys((math.asin(s3), math.pi - math.asin(s3))):
            phi = q3 - math.pi / 2  # forearm angle relative to the upper arm, in the arm's plane
            q2 = math.atan2(-v, u) - math.atan2(D4 * math.sin(phi), A2 + D4 * math.cos(phi))
            out.append((q1, q2, q3))
    return out


def wrist_joints(r36: np.ndarray, q4_hint: float = 0.0) -> list[tuple[float, float, float]]:
    """(q4, q5, q6) giving the wrist rotation ``r36``: two branches, one at the q5 = 0 singularity."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r36.tolist()
    c5 = min(1.0, max(-1.0, -r12))
    s5 = math.sqrt(max(1.0 - c5**2, 0.0))
    if s5 < SINGULAR:  # q4 and q6 turn about the same axis: keep q4, give the rest to q6
        q4 = q4_hint
        m = _rot36_to_r4(q4).T @ r36  # the remaining rotation of rows 5 and 6
        q5 = 0.0 if c5 > 0 else math.pi
        q6 = math.atan2(-m[0, 1], m[0, 0]) if c5 > 0 else math.atan2(m[0, 1], -m[0, 0])
        return [(q4, q5, float(q6))]
    out = []
    for s in (s5, -s5):
        q4 = math.atan2(r22 / s, r02 / s)
        q5 = math.atan2(s, c5)
        q6 = math.atan2(-r11 / s, r10 / s)
        out.append((q4, q5, q6))
    return out


def elbow_up(q1: float, q2: float, q3: float) -> bool:
    """Whether the elbow sits above the shoulder–wrist line (the ARM controller's choice)."""
    s2, c2, s23, c23 = math.sin(q2), math.cos(q2), math.sin(q2 + q3), math.cos(q2 + q3)
    elbow_v = -A2 * s2
    wrist_u, wrist_v = A2 * c2 + D4 * s23, -A2 * s2 + D4 * c23
    elbow_u = A2 * c2
    # height of the shoulder–wrist line under the elbow (the line may be vertical: compare across it)
    cross = wrist_u * elbow_v - wrist_v * elbow_u
    return cross > 0 if wrist_u >= 0 else cross < 0


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def arm_ik(wrist_pose: np.ndarray, elbow_up_only: bool = False) -> list[np.ndarray]:
    """All 6-joint solutions placing frame 6 at ``wrist_pose`` (4x4, arm frame), angles in (−π, π]; with
    ``elbow_up_only`` those of the elbow-up branches (the wrist is not solved for the others)."""
    sols = []
    for q1, q2, q3 in wrist_centre_joints(wrist_pose[:3, 3]):
        if elbow_up_only and not elbow_up(q1, q2, q3):
            continue
        r36 = _rot03(q1, q2, q3).T @ wrist_pose[:3, :3]
        for q4, q5, q6 in wrist_joints(r36):
            sols.append(np.array([_wrap(q1), _wrap(q2), _wrap(q3), _wrap(q4), _wrap(q5), _wrap(q6)]))
    return sols
