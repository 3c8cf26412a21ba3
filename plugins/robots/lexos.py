"""L-Exos arm exoskeleton (after Loconsole et al.): 4 actuated DoF, right arm.

A 3R shoulder whose axes meet at the shoulder centre — q1 abduction (about the
backward axis), q2 flexion (about the left axis), q3 internal/external rotation
(about the upper arm) — then q4 elbow flexion. Base frame at the shoulder
centre: x forward, y left, z up; at q = 0 the arm hangs straight down.
q2 = -90° is the arm held forward, q4 = -90° a right-angle elbow, q3 > 0 turns
the forearm outward. The measured-only pronation/supination q5 is a passive
joint about the forearm axis just before the handle (simulated, readable by a
joint encoder, locked in the control model); the handle centre lies on its axis,
so it does not move the hand position.

The arm is redundant for hand *position*: the elbow can swing on a circle
around the shoulder-hand line. :func:`position_ik` parametrises that swivel
angle and solves the rest in closed form, vectorised over many points, which
is what makes the workspace look-up table cheap to build.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numba import njit
from pydantic import Field

from rehabkit.kinematics import (
    JointSpec,
    KinematicChain,
    PoseSpec,
    RobotModel,
    SafeStop,
    Strap,
    Wearable,
    build_chain_mjcf,
    links_and_limits,
    rot_x,
    trans,
)
from rehabkit.plugin import Context, RandomReach, Robot, StrictModel, WorkspaceTable, hookimpl, load_yaml
from rehabkit.workspaces import VoxelWorkspace, build_workspace, random_inner, random_inner_not_straight

UPPER_ARM, FOREARM = 0.30, 0.35  # [m], adult anthropometry (no public L-Exos figures)


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


HANDLE = 0.05  # q5 axis to the handle centre, along the forearm [m]


def lexos_chain(l1: float = UPPER_ARM, l2: float = FOREARM, with_q5: bool = False) -> KinematicChain:
    """Shoulder (3 axes through one point), upper arm ``l1``, elbow, forearm ``l2`` to the handle.

    The handle frame has z along the forearm. ``with_q5`` adds the passive
    pronation/supination joint about that axis, ``HANDLE`` before the handle.
    """
    base = np.eye(4)
    base[:3, :3] = np.column_stack([[0, 0, -1], [0, -1, 0], [-1, 0, 0]])  # joint 1 axis: backward
    head = (base, rot_x(np.pi / 2), _rot_y(np.pi / 2), trans(z=l1) @ _rot_y(-np.pi / 2))
    if with_q5:
        return KinematicChain((*head, trans(x=l2 - HANDLE) @ _rot_y(np.pi / 2), trans(z=HANDLE)), ("revolute",) * 5)
    return KinematicChain((*head, trans(x=l2) @ _rot_y(np.pi / 2)), ("revolute",) * 4)


def position_ik(p: np.ndarray, swivel: np.ndarray, l1: float = UPPER_ARM, l2: float = FOREARM) -> np.ndarray:
    """Joint values putting the hand at ``p`` for each swivel angle.

    Args:
        p: Hand positions (N, 3) in the base frame [m].
        swivel: Elbow angles on its circle around the shoulder-hand line (M,) [rad].

    Returns:
        (N, M, 4) joint values [rad]; NaN where the distance is out of reach.
    """
    p = np.atleast_2d(np.asarray(p, dtype=float))
    r = np.linalg.norm(p, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        c4 = (r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2)
        q4 = -np.arccos(np.where(np.abs(c4) <= 1.0, c4, np.nan))  # elbow flexion is negative
        ph = p / r[:, None]
        cos_a = np.clip((l1 * l1 + r * r - l2 * l2) / (2 * l1 * r), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a**2)
    # an orthonormal pair around the shoulder-hand line (any will do: swivel samples the whole circle)
    helper = np.where(np.abs(ph[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    n1 = np.cross(ph, helper)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(ph, n1)
    cphi, sphi = np.cos(swivel)[None, :, None], np.sin(swivel)[None, :, None]
    around = cphi * n1[:, None, :] + sphi * n2[:, None, :]
    e = l1 * (cos_a[:, None, None] * ph[:, None, :] + sin_a[:, None, None] * around)  # elbow positions
    u = e / l1  # upper-arm direction = (-sin q2, -cos q2 sin q1, -cos q2 cos q1)
    q2 = -np.arcsin(np.clip(u[..., 0], -1.0, 1.0))
    q1 = np.arctan2(-u[..., 1], -u[..., 2])
    f = (p[:, None, :] - e) / l2  # forearm direction, expressed in the frame after q1, q2:
    c1, s1, c2, s2 = np.cos(q1), np.sin(q1), np.cos(q2), np.sin(q2)
    fx = c2 * f[..., 0] - s2 * s1 * f[..., 1] - s2 * c1 * f[..., 2]
    fy = c1 * f[..., 1] - s1 * f[..., 2]
    q3 = np.arctan2(-fy, fx)
    return np.stack([q1, q2, q3, np.broadcast_to(q4[:, None], q1.shape)], axis=-1)


@njit(cache=True, nogil=True)
def _any_swivel_in_range(p, swivel, l1, l2, lower, upper):  # pragma: no cover - compiled
    """:func:`position_ik`'s arithmetic point by point, each point's swivel samples in turn until one puts every
    joint in its range: a workspace table tests ~10⁵-10⁶ points, most of them reachable at an early sample, where
    the (N, M, 4) arrays of the vectorised form cost ~57 µs a point."""
    out = np.zeros(len(p), np.bool_)
    for k in range(len(p)):
        x, y, z = p[k, 0], p[k, 1], p[k, 2]
        r = math.sqrt(x * x + y * y + z * z)
        c4 = (r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2)
        if not abs(c4) <= 1.0:
            continue
        q4 = -math.acos(c4)
        if not (lower[3] <= q4 <= upper[3]):
            continue
        hx, hy, hz = x / r, y / r, z / r
        cos_a = min(max((l1 * l1 + r * r - l2 * l2) / (2 * l1 * r), -1.0), 1.0)
        sin_a = math.sqrt(1.0 - cos_a * cos_a)
        ax, ay, az = (0.0, 0.0, 1.0) if abs(hz) < 0.9 else (1.0, 0.0, 0.0)
        n1x, n1y, n1z = hy * az - hz * ay, hz * ax - hx * az, hx * ay - hy * ax
        norm = math.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
        n1x, n1y, n1z = n1x / norm, n1y / norm, n1z / norm
        n2x, n2y, n2z = hy * n1z - hz * n1y, hz * n1x - hx * n1z, hx * n1y - hy * n1x
        for phi in swivel:
            cphi, sphi = math.cos(phi), math.sin(phi)
            ex = l1 * (cos_a * hx + sin_a * (cphi * n1x + sphi * n2x))
            ey = l1 * (cos_a * hy + sin_a * (cphi * n1y + sphi * n2y))
            ez = l1 * (cos_a * hz + sin_a * (cphi * n1z + sphi * n2z))
            q2 = -math.asin(min(max(ex / l1, -1.0), 1.0))
            if not (lower[1] <= q2 <= upper[1]):
                continue
            q1 = math.atan2(-ey / l1, -ez / l1)
            if not (lower[0] <= q1 <= upper[0]):
                continue
            fx, fy, fz = (x - ex) / l2, (y - ey) / l2, (z - ez) / l2
            c1, s1, c2, s2 = math.cos(q1), math.sin(q1), math.cos(q2), math.sin(q2)
            q3 = math.atan2(-(c1 * fy - s1 * fz), c2 * fx - s2 * s1 * fy - s2 * c1 * fz)
            if lower[2] <= q3 <= upper[2]:
                out[k] = True
                break
    return out


@dataclass(frozen=True)
class SwivelReachability:
    """Picklable reachability test: some swivel sample satisfies every joint range."""

    l1: float
    l2: float
    lower: np.ndarray
    upper: np.ndarray
    swivel: np.ndarray

    def __call__(self, p: np.ndarray) -> np.ndarray:
        return _any_swivel_in_range(np.ascontiguousarray(p, dtype=float), np.asarray(self.swivel, float),
                                    float(self.l1), float(self.l2), np.asarray(self.lower, float),
                                    np.asarray(self.upper, float))


def lexos_wearable(l1: float, l2: float) -> Wearable:
    """The person's shoulder centre where the three shoulder axes meet (the base origin), facing the base's x;
    a cuff on the upper arm (60 % of the way to the elbow) and one on the forearm, a hand's breadth before the
    handle."""
    return Wearable(shoulder=(0.0, 0.0, 0.0), forward=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0),
                    straps=(Strap("upper_arm", "q3_rotation_link", (0.0, 0.0, 0.6 * l1)),
                            Strap("forearm", "q4_elbow_link", (max(0.05, l2 - 0.15), 0.0, 0.0))))


class LexosConfig(StrictModel):
    """L-Exos arm: segment lengths, placement, stop behaviour."""

    upper_arm: float = Field(UPPER_ARM, gt=0, description="shoulder centre to elbow [m]")
    forearm: float = Field(FOREARM, gt=0, description="elbow to handle [m]")
    base: PoseSpec = Field(PoseSpec(position=(0.0, 0.0, 1.2)), description="shoulder centre in the world")
    swivel_samples: int = Field(120, ge=8, description="elbow-circle samples in reachability tests")
    safe_stop: SafeStop = "hold"


def _joint_specs() -> tuple[list[JointSpec], list[JointSpec]]:
    data = load_yaml(resources.files(__package__).joinpath("lexos_joints.yaml").read_text())
    return ([JointSpec.model_validate(j) for j in data["joints"]],
            [JointSpec.model_validate(j) for j in data.get("passive", [])])


class LexosRobot(Robot, WorkspaceTable, RandomReach):
    """L-Exos 4-DoF arm exoskeleton: 3R shoulder + elbow, paper's joint ranges, concave workspace."""

    ik_kind = "position"  # four joints place the hand; the elbow's swivel is the redundancy

    def __init__(self, config: LexosConfig, context: Context | None = None):
        self.config = config
        self.lengths = (config.upper_arm, config.forearm)
        joints, passive = _joint_specs()
        links, limits = links_and_limits(joints)
        passive_links, _ = links_and_limits(passive)
        self.chain = lexos_chain(*self.lengths)  # the four driven joints: all the hand position depends on
        xml = build_chain_mjcf("lexos", lexos_chain(*self.lengths, with_q5=True), links + passive_links,
                               base_radius=0.06, ee_site="handle")
        self.model = RobotModel("lexos", xml, [j.name for j in joints], limits, "handle",
                                base_pose=config.base.matrix(), safe_stop=config.safe_stop,
                                passive_joints=[j.name for j in passive], wearable=lexos_wearable(*self.lengths))
        self.swivel = np.linspace(-np.pi, np.pi, config.swivel_samples, endpoint=False)
        self._own = (limits.lower.copy(), limits.upper.copy())  # before a patient's ranges narrow them

    def fk(self, q: np.ndarray) -> np.ndarray:
        return self.chain.fk(q)

    def fk_batch(self, qs: np.ndarray) -> np.ndarray:
        return self.chain.fk_batch(qs)

    def position_ik(self, p: np.ndarray) -> np.ndarray:
        """(N, swivel_samples, 4) joint values for hand positions ``p`` (base frame)."""
        return position_ik(p, self.swivel, *self.lengths)

    def ik(self, pose: np.ndarray, reference: np.ndarray | None = None) -> list[np.ndarray]:
        """Joint values putting the hand at the pose's position (4 DoF: position only), one per elbow swivel
        sample within every joint range; nearest ``reference`` first (default: the middle of the ranges)."""
        lim = self.model.limits
        q = self.position_ik(np.asarray(pose, float)[:3, 3])[0]
        with np.errstate(invalid="ignore"):
            q = q[np.all((q >= lim.lower) & (q <= lim.upper), axis=1)]
        ref = 0.5 * (lim.lower + lim.upper) if reference is None else np.asarray(reference, float)
        return list(q[np.argsort(np.linalg.norm(q - ref, axis=1))])

    def reachable(self, p: np.ndarray) -> np.ndarray:
        """Whether some elbow swivel puts the hand at each ``p`` within every joint range."""
        return self._reachability(self.model.limits.lower, self.model.limits.upper)(p)

    def _reachability(self, lower: np.ndarray, upper: np.ndarray) -> SwivelReachability:
        return SwivelReachability(*self.lengths, lower, upper, self.swivel)

    def workspace(self, resolution: float = 0.01, progress: bool = True, use_cache: bool = True) -> VoxelWorkspace:
        """The voxel look-up table of the hand's workspace (base frame), cached on disk (the default arm's at 1 cm
        ships beside this module: ``lexos_workspace.npz``, a copy of the cache file built by this method). With
        ranges narrowed within the arm's own (a patient's), only the voxels its own table reaches are tested."""
        lim = self.model.limits
        superset = None
        if (np.any(lim.lower != self._own[0]) or np.any(lim.upper != self._own[1])) and \
                np.all(lim.lower >= self._own[0]) and np.all(lim.upper <= self._own[1]):
            superset = self._table(*self._own, resolution, progress, use_cache)
        return self._table(lim.lower, lim.upper, resolution, progress, use_cache, superset)

    def _table(self, lower, upper, resolution, progress, use_cache, superset=None) -> VoxelWorkspace:
        key = f"lexos|{self.lengths}|{lower.round(9).tolist()}|{upper.round(9).tolist()}|{len(self.swivel)}"
        return build_workspace(key, self.chain.fk_batch, self._reachability(lower, upper), lower, upper, resolution,
                               progress=progress, use_cache=use_cache, superset=superset,
                               shipped=Path(str(resources.files(__package__).joinpath("lexos_workspace.npz"))))

    def random_reach(self, rng: np.random.Generator, not_straight_from: np.ndarray | None = None) -> np.ndarray:
        """An inner voxel of the workspace table, drawn uniformly (see :mod:`rehabkit.workspace.sampling`)."""
        ws = self.workspace(progress=False)
        if not_straight_from is None:
            return random_inner(ws, rng)
        return random_inner_not_straight(ws, rng, not_straight_from)


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("lexos", config=LexosConfig, factory=LexosRobot)
