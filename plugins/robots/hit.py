"""HIT modular upper-limb exoskeleton: 6 DoF, shoulder/elbow/wrist modules of 2 DoF each.

Kinematics after Li et al. (HIT): the modified-DH table describes the
*inverted* exoskeleton, from the hand (frame 0) to the shoulder (frame 6)::

    i   a_{i-1}  alpha_{i-1}  d_i   (theta_i variable)
    1   -l3      0            0
    2   0        90°          l2
    3   0        90°          0
    4   0        -90°         l1
    5   0        -90°         0
    6   0        -90°         0

with l1 the upper arm, l2 the forearm and l3 the hand. Inverting that chain
gives the real exoskeleton: its pose is ``A = T⁻¹`` and its joints are
``Θi = −θ(7−i)``. The shoulder's three axes meet at a point while the wrist's
do not, which is why inverse kinematics is solved on the inverted chain, where
the wrist-centre position depends on θ1..θ3 only.

Link masses, radii and joint limits are not in the paper; the values in
``hit_joints.yaml`` are plausible for an adult-sized exoskeleton and say so.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources

import numpy as np
from pydantic import ConfigDict, Field

from rehabkit.kinematics import (
    DHRobotSpec,
    DHRow,
    DHRowSpec,
    JointSpec,
    KinematicChain,
    PoseSpec,
    SafeStop,
    Strap,
    Wearable,
    build_dh_robot,
    inv_se3,
    mdh_transform,
)
from rehabkit.plugin import Context, Robot, StrictModel, hookimpl, load_yaml

L1, L2, L3 = 0.313, 0.252, 0.1  # upper arm, forearm, hand [m] (paper's values)


def mdh_rows(l1: float = L1, l2: float = L2, l3: float = L3) -> list[DHRow]:
    """The inverted exoskeleton's modified-DH table (hand → shoulder)."""
    h = np.pi / 2
    return [DHRow(-l3, 0, 0), DHRow(0, h, l2), DHRow(0, h, 0), DHRow(0, -h, l1), DHRow(0, -h, 0), DHRow(0, -h, 0)]


def _wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def fk(q: np.ndarray, l1: float = L1, l2: float = L2, l3: float = L3) -> np.ndarray:
    """⁰₆A: hand pose in the shoulder (base) frame for exoskeleton joints Θ = ``q`` [rad]."""
    theta = -np.asarray(q, dtype=float)[::-1]
    t = np.eye(4)
    for row, th in zip(mdh_rows(l1, l2, l3), theta):
        t = t @ mdh_transform(row, th)
    return inv_se3(t)


@lru_cache(maxsize=8)
def _inverted_chain(l1: float, l2: float, l3: float) -> KinematicChain:
    return KinematicChain.from_dh(mdh_rows(l1, l2, l3), "modified")


def fk_many(qs: np.ndarray, l1: float = L1, l2: float = L2, l3: float = L3) -> np.ndarray:
    """:func:`fk` for many joint vectors (N, 6) at once: the inverted chain vectorised over the batch, inverted."""
    t = _inverted_chain(l1, l2, l3).fk_batch(-np.atleast_2d(np.asarray(qs, float))[:, ::-1])
    out = np.zeros_like(t)
    rot = np.transpose(t[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = rot
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rot, t[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def ik_inverted(T: np.ndarray, l1: float = L1, l2: float = L2, l3: float = L3, tol: float = 1e-9) -> list[np.ndarray]:
    """Every θ of the inverted chain with ``∏ T_i(θ_i) = T`` (closed form, up to 8 branches)."""
    rows = mdh_rows(l1, l2, l3)
    px, py, pz = T[:3, 3]
    x = px + l3  # frame-1 origin sits at -l3 on x0
    k1 = (x * x + py * py + pz * pz - l1 * l1 - l2 * l2) / (2 * l1 * l2)  # = cos θ3
    if abs(k1) > 1 + tol:
        return []  # wrist centre out of reach
    k1 = float(np.clip(k1, -1.0, 1.0))
    c = l2 + k1 * l1
    radicand = x * x + py * py - c * c
    if radicand < -tol:
        return []
    root = np.sqrt(max(radicand, 0.0))
    out: list[np.ndarray] = []
    for sign3 in (1.0, -1.0):
        th3 = np.arctan2(sign3 * np.sqrt(1.0 - k1 * k1), k1)
        s3 = np.sin(th3)
        for sign1 in (1.0, -1.0):
            th1 = np.arctan2(py, x) + np.arctan2(c, sign1 * root)
            k2 = np.cos(th1) * px + np.sin(th1) * py + np.cos(th1) * l3
            # The paper's θ2 = atan2(-l1 s3, ±√(pz² + k2² - l1² s3²)) - atan2(k2, pz). The radicand is
            # identically zero on a consistent pose (pz = -l1 s2 s3, k2 = -l1 c2 s3), and the square root of
            # its rounding residue would cost ~1e-8 rad, so it is taken as exactly zero.
            th2 = np.arctan2(-l1 * s3, 0.0) - np.arctan2(k2, pz)
            t03 = mdh_transform(rows[0], th1) @ mdh_transform(rows[1], th2) @ mdh_transform(rows[2], th3)
            m = inv_se3(t03) @ T  # = T34 T45 T56: column 3 is (-c4 s5, ., s4 s5)
            for wrist in (1.0, -1.0):  # s5 > 0 and s5 < 0: the wrist flip
                # s5 = 0: θ4 and θ6 share an axis; fix θ4 and let θ6 take the rest
                singular = np.hypot(m[2, 2], m[0, 2]) < 1e-12
                th4 = 0.0 if singular else np.arctan2(wrist * m[2, 2], -wrist * m[0, 2])
                n = inv_se3(mdh_transform(rows[3], th4)) @ m  # = T45 T56
                th5 = np.arctan2(-n[0, 2], -n[2, 2])
                th6 = np.arctan2(-n[1, 0], -n[1, 1])
                out.append(np.array([th1, th2, th3, th4, th5, th6]))
    return out


def ik(A: np.ndarray, l1: float = L1, l2: float = L2, l3: float = L3, tol: float = 1e-7) -> list[np.ndarray]:
    """Every exoskeleton solution Θ (wrapped to (-π, π]) with ``fk(Θ) = A``.

    Solved on the inverted chain (``T = A⁻¹``) and mapped back with Θi = −θ(7−i).
    Branches that do not reproduce ``A`` within ``tol`` (near-singular rounding)
    are dropped, and duplicates removed.
    """
    A = np.asarray(A, dtype=float)
    thetas = ik_inverted(inv_se3(A), l1, l2, l3)
    if not thetas:
        return []
    qs = _wrap(-np.array(thetas)[:, ::-1])
    reach = np.abs(fk_many(qs, l1, l2, l3) - A).max(axis=(1, 2))  # every branch checked in one batch
    sols: list[np.ndarray] = []
    for q, err in zip(qs, reach):
        if err <= tol and all(np.abs(_wrap(q - s)).max() > 1e-6 for s in sols):
            sols.append(q)
    return sols


def hit_wearable(l1: float) -> Wearable:
    """The person's shoulder centre where the shoulder module's axes meet (the base origin), facing the base's -x;
    a cuff on the upper arm (on the link turning with the humerus, 40 % of the way back from the elbow) and one on
    the forearm, 15 cm from the elbow."""
    return Wearable(shoulder=(0.0, 0.0, 0.0), forward=(-1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0),
                    straps=(Strap("upper_arm", "elbow_1_link", (0.0, 0.0, 0.4 * l1)),
                            Strap("forearm", "elbow_2_link", (0.0, -0.15, 0.0))))


class HitConfig(StrictModel):
    """HIT exoskeleton: segment lengths, base placement and stop behaviour."""

    # built where first used: the registry's model of the plugin (this one with its `type`), built as it is
    # registered, is what a scenario is validated with (~0.5 ms less of every run's start)
    model_config = ConfigDict(defer_build=True)

    l1: float = Field(L1, gt=0, description="upper arm [m]")
    l2: float = Field(L2, gt=0, description="forearm [m]")
    l3: float = Field(L3, gt=0, description="hand [m]")
    base: PoseSpec = Field(
        PoseSpec(position=(0.0, 0.0, 1.3), rpy_deg=(0.0, 0.0, 180.0)),
        description="shoulder centre in the world; base z is up, the arm reaches along base -x",
    )
    safe_stop: SafeStop = "hold"
    brakes_nm: list[float] | None = Field(None, min_length=6, max_length=6,
                                          description="holding brakes per joint [N·m], engaged when the torque goes "
                                          "off (safety stop categories 0 and 1); default none (the paper's robot "
                                          "names none)")


def _joint_specs() -> list[JointSpec]:
    text = resources.files(__package__).joinpath("hit_joints.yaml").read_text()
    return [JointSpec.model_validate(j) for j in load_yaml(text)["joints"]]


class HitRobot(Robot):
    """HIT 6-DoF modular upper-limb exoskeleton (MDH table, reverse-coordinate analytic IK)."""

    def __init__(self, config: HitConfig, context: Context | None = None):
        self.config = config
        rows = [
            DHRowSpec(a=r.a, alpha_deg=float(np.degrees(r.alpha)), d=r.d)
            for r in mdh_rows(config.l1, config.l2, config.l3)
        ]
        self.spec = DHRobotSpec(
            name="hit", convention="modified", reverse=True, table=rows, joints=_joint_specs(),
            base=config.base, safe_stop=config.safe_stop,
        )
        if config.brakes_nm is not None:
            self.spec = self.spec.model_copy(update={"joints": [j.model_copy(update={"brake": b}) for j, b in
                                                                 zip(self.spec.joints, config.brakes_nm)]})
        self.model = build_dh_robot(self.spec)
        self.model.wearable = hit_wearable(config.l1)
        self._lengths = (config.l1, config.l2, config.l3)

    def fk(self, q: np.ndarray) -> np.ndarray:
        """⁰₆A for joints ``q`` [rad], in the shoulder frame (the batch form: ~10x faster than the product of
        4x4s in :func:`fk`, which stays as the paper's formulation)."""
        return fk_many(np.asarray(q, float)[None], *self._lengths)[0]

    def fk_batch(self, qs: np.ndarray) -> np.ndarray:
        """⁰₆A for many joint vectors (N, 6) at once: the same chain, vectorised over the batch."""
        return fk_many(qs, *self._lengths)

    def ik(self, pose: np.ndarray, reference: np.ndarray | None = None) -> list[np.ndarray]:
        """All joint solutions for hand pose ``pose`` (4x4, shoulder frame)."""
        return ik(pose, *self._lengths)

    def chain(self) -> KinematicChain:
        return self.spec.chain()


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("hit", config=HitConfig, factory=HitRobot)
