"""CaPaMan, the Cassino Parallel Manipulator: 3 cranks move a plate carrying a tool (after Carbone et al.).

The mechanism's MJCF is built in :mod:`capaman_mjcf`, its kinematics are in
:mod:`capaman_kinematics`; the passive joints' values that assemble the
mechanism for given cranks come from its forward kinematics.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field
from rehabkit_plugins.robots.contracts import ClusterPoints
from scipy.optimize import least_squares

from rehabkit.kinematics import JointLimits, PoseSpec, RobotModel, SafeStop, matrix_to_quat_wxyz
from rehabkit.plugin import Context, PassiveJoints, Robot, StrictModel, hookimpl

from .capaman_kinematics import CapamanGeometry, forward, forward_jacobian, inverse
from .capaman_mjcf import MASS, build_capaman_mjcf


class CapamanConfig(StrictModel):
    """Dimensions (commonly cited CaPaMan values), crank range, tool and placement."""

    a: float = Field(0.200, gt=0, description="frame link = coupler [m]")
    b: float = Field(0.080, gt=0, description="crank = follower [m]")
    h: float = Field(0.100, gt=0, description="bar from the coupler's middle to the slider [m]")
    r_base: float = Field(0.110, gt=0, description="leg planes' distance from the fixed plate's centre [m]")
    r_plate: float = Field(0.110, gt=0, description="radius of the plate's spherical joints [m]")
    crank_range_deg: tuple[float, float] = (45.0, 135.0)
    crank_speed_deg_s: float = Field(120.0, gt=0)
    crank_torque: float = Field(10.0, gt=0, description="[N·m]")
    tool: tuple[float, float, float] = Field((0.0, 0.0, 0.12), description="tool tip in the plate frame [m]")
    tool_radius: float = Field(0.006, gt=0)
    plate_mass: float = Field(0.6, gt=0, description="[kg]")
    base: PoseSpec = Field(PoseSpec(position=(0.0, 0.0, 0.75)), description="fixed plate on a table")
    safe_stop: SafeStop = "hold"


class CapamanRobot(Robot, PassiveJoints, ClusterPoints):
    """CaPaMan 3-DoF parallel manipulator: parallelogram legs, sliders, spherical joints, a tool on the plate."""

    ik_kind = "position"

    def __init__(self, config: CapamanConfig, context: Context | None = None):
        self.config = config
        self.geo = CapamanGeometry(config.a, config.b, config.h, config.r_base, config.r_plate)
        lo, hi = np.radians(config.crank_range_deg)
        limits = JointLimits(
            np.full(3, lo),
            np.full(3, hi),
            np.full(3, np.radians(config.crank_speed_deg_s)),
            np.full(3, config.crank_torque),
        )
        passive = [f"{n}_{k}" for k in (1, 2, 3) for n in ("coupler", "slide", "follower")] + ["plate_ball"]
        self.model = RobotModel(
            "capaman",
            build_capaman_mjcf(self.geo, config.crank_range_deg, config.plate_mass, config.tool, config.tool_radius),
            [f"alpha_{k}" for k in (1, 2, 3)],
            limits,
            "tool_tip",
            base_pose=config.base.matrix(),
            safe_stop=config.safe_stop,
            passive_joints=passive,
        )
        self.tool = np.asarray(config.tool, float)

    def plate_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, R, res = forward(self.geo, np.atleast_2d(q))
        if res.max() > 1e-9:
            raise ValueError(f"capaman: no assembly for cranks {np.degrees(q).round(2).tolist()} deg")
        return p[0], R[0]

    def body_poses(self, body: str, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The movable plate's pose (its centre, ``plate``) or the tool tip's (``tool_tip``) for crank triples,
        by the closed-loop kinematics (Pinocchio's tree cannot close the legs' loops)."""
        if body not in ("plate", "tool_tip"):
            raise ValueError(f"robot 'capaman' predicts the poses of 'plate' and 'tool_tip', not '{body}'")
        p, R, _ = forward(self.geo, np.atleast_2d(qs))
        return (p, R) if body == "plate" else (p + R @ self.tool, R)

    def jacobian(self, q: np.ndarray, frame: str | None = None) -> np.ndarray:
        """6×3: the tool tip's (default) or the plate's (``plate``) linear and angular velocity per crank rate,
        base-frame axes, by implicit differentiation of the leg equations."""
        if frame not in (None, "tool_tip", "plate"):
            raise ValueError(f"robot 'capaman' gives the Jacobians of 'plate' and 'tool_tip', not '{frame}'")
        q = np.asarray(q, float)
        p, R = self.plate_pose(q)
        d = forward_jacobian(self.geo, q, p, R)
        if frame == "plate":
            return d
        return np.vstack([d[:3] - np.cross(R @ self.tool, d[3:].T).T, d[3:]])

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """The cranks' inertia matrix (3×3): the whole mechanism's (MuJoCo's tree, every leg and the plate)
        seen through the closed loops, Gᵀ M G with G the tree's joint velocities per crank rate."""
        import mujoco

        if getattr(self, "_mj", None) is None:
            self._mj = mujoco.MjModel.from_xml_string(self.model.mjcf)
        mj = self._mj
        data = mujoco.MjData(mj)

        def qpos(cranks: np.ndarray) -> np.ndarray:
            out = mj.qpos0.copy()
            for name, value in {**{f"alpha_{k + 1}": [cranks[k]] for k in range(3)},
                                **self.passive_state(cranks)}.items():
                adr = mj.jnt_qposadr[mj.joint(name).id]
                out[adr:adr + len(value)] = value
            return out

        q = np.asarray(q, float)
        eps, G, column = 1e-6, np.empty((mj.nv, 3)), np.empty(mj.nv)
        for k in range(3):
            step = np.zeros(3)
            step[k] = eps
            mujoco.mj_differentiatePos(mj, column, 2 * eps, qpos(q - step), qpos(q + step))
            G[:, k] = column
        data.qpos[:] = qpos(q)
        mujoco.mj_forward(mj, data)
        M = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, data, M)
        return G.T @ M @ G

    def fk_batch(self, qs: np.ndarray) -> np.ndarray:
        p, R, _ = forward(self.geo, np.atleast_2d(qs))
        out = np.tile(np.eye(4), (len(p), 1, 1))
        out[:, :3, :3] = R
        out[:, :3, 3] = p + R @ self.tool
        return out

    def fk(self, q: np.ndarray) -> np.ndarray:
        """Tool-tip pose in the base frame (numerical forward kinematics)."""
        return self.fk_batch(np.asarray(q, float)[None])[0]

    def ik(self, pose: np.ndarray, reference: np.ndarray | None = None) -> list[np.ndarray]:
        """Cranks within their range putting the tool tip at ``pose``'s position (orientation follows).

        Bounded least squares from a few starts: the all-vertical home pose is a
        singularity of the tool-tip map, so a plain Newton start there fails.
        """
        goal = np.asarray(pose, float)[:3, 3]
        lim = self.model.limits
        solved: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def pose_at(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            key = a.tobytes()
            if key not in solved:
                p, R, _ = forward(self.geo, a[None])
                solved.clear()
                solved[key] = p[0], R[0]
            return solved[key]

        def error(a: np.ndarray) -> np.ndarray:
            p, R = pose_at(a)
            return p + R @ self.tool - goal

        def jacobian(a: np.ndarray) -> np.ndarray:
            # the tool tip p + R t moves by dp − (R t)× dφ: analytic, one forward solve a step instead of four
            p, R = pose_at(a)
            d = forward_jacobian(self.geo, a, p, R)
            rt = R @ self.tool
            return d[:3] - np.cross(rt, d[3:].T).T

        found: list[np.ndarray] = []
        for start in (np.full(3, 1.4), np.full(3, 1.75), np.array([1.3, 1.6, 1.9]), np.array([1.9, 1.6, 1.3])):
            sol = least_squares(error, start, jac=jacobian, bounds=(lim.lower, lim.upper), xtol=1e-15, ftol=1e-15,
                                gtol=1e-15)
            if np.linalg.norm(sol.fun) < 1e-9 and all(np.abs(sol.x - f).max() > 1e-6 for f in found):
                found.append(sol.x)
        return found

    link_radius = 0.008  # thickest leg link; obstacles are grown by this for axis points

    def cluster_points(self, qs: np.ndarray) -> np.ndarray:
        """Points representing the whole moving mechanism, (N, P, 3) in the base frame, for N crank triples.

        Legs (cranks, followers, couplers, bars, sliders) and the tool by points
        along their axes every centimetre or less (test them against obstacles
        grown by ``link_radius``); the movable plate by points on its two faces and rim.
        """
        qs = np.atleast_2d(np.asarray(qs, float))
        g = self.geo
        p, R, _ = forward(g, qs)
        _, slide, _ = inverse(g, p, R)
        t, e, o = g.tangent, g.radial, g.centres  # (3, 3) each, one row per leg
        z = np.array([0.0, 0.0, 1.0])
        d = np.cos(qs)[..., None] * t + np.sin(qs)[..., None] * z  # crank directions (N, 3, 3)
        p1, p2 = o - 0.5 * g.a * t, o + 0.5 * g.a * t
        mid = o + g.b * d
        u = lambda n: np.linspace(0.0, 1.0, n)[:, None]  # noqa: E731
        parts = [
            p1[None, :, None] + g.b * d[:, :, None] * u(9),  # cranks
            p2[None, :, None] + g.b * d[:, :, None] * u(9),  # followers
            (p1 + 0.0)[None, :, None] + g.b * d[:, :, None] + g.a * t[None, :, None] * u(21),  # couplers
            mid[:, :, None] + g.h * z * u(11),  # bars
            (mid + g.h * z)[:, :, None] + slide[..., None, None] * e[None, :, None] * u(5),  # sliders' travel
        ]
        legs = np.concatenate(parts, axis=2).reshape(len(qs), -1, 3)
        rings = [(0.0, 1)] + [(r, int(np.ceil(2 * np.pi * r / 0.02))) for r in np.linspace(0.03, g.r_plate + 0.015, 4)]
        local = [
            (r * np.cos(a), r * np.sin(a), h)
            for r, n in rings
            for a in np.linspace(0, 2 * np.pi, n, endpoint=False)
            for h in (-0.006, 0.006)
        ]
        local += [tuple(self.tool * s) for s in np.linspace(0.05, 1.0, 24)]
        plate = p[:, None, :] + np.einsum("nij,pj->npi", R, np.array(local))
        return np.concatenate([legs, plate], axis=1)

    def passive_state(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Passive joint values assembling the mechanism at cranks ``q``."""
        p, R = self.plate_pose(q)
        _, slide, _ = inverse(self.geo, p[None], R[None])
        state = {"plate_ball": matrix_to_quat_wxyz(R)}
        for k in range(3):
            state[f"coupler_{k + 1}"] = np.array([-q[k]])
            state[f"follower_{k + 1}"] = np.array([q[k]])
            state[f"slide_{k + 1}"] = np.array([slide[0, k]])
        return state

    def potential(self, q: np.ndarray) -> np.ndarray:
        """Gravitational potential energy [J] (base frame, z up) for rows of crank angles."""
        q = np.atleast_2d(q)
        b, h, g = self.geo.b, self.geo.h, 9.81
        s = np.sin(q)
        legs = (
            (MASS["crank"] / 2 + MASS["follower"] / 2) * b * s
            + MASS["coupler"] * b * s
            + MASS["bar"] * (b * s + h / 2)
            + MASS["slider"] * (b * s + h)
        )
        p, R, _ = forward(self.geo, q)
        tool_com = p + R @ (self.tool / 2)
        return g * (legs.sum(axis=1) + self.config.plate_mass * p[:, 2] + MASS["tool"] * tool_com[:, 2])

    def gravity_torque_exact(self, qs: np.ndarray) -> np.ndarray:
        """Crank torques holding the mechanism against gravity, ∂U/∂α by central differences, rows of ``qs``."""
        qs = np.atleast_2d(np.asarray(qs, float))
        eps = 1e-6
        steps = np.concatenate([qs[:, None, :] + np.eye(3) * eps, qs[:, None, :] - np.eye(3) * eps], axis=1)
        u = self.potential(steps.reshape(-1, 3)).reshape(len(qs), 6)
        return (u[:, :3] - u[:, 3:]) / (2 * eps)

    def _gravity_table(self) -> tuple:
        if getattr(self, "_gravity", None) is None:
            lim = self.model.limits
            n = [int(round(np.degrees(hi - lo) / 5)) + 1 for lo, hi in zip(lim.lower, lim.upper)]
            axes = [np.linspace(lo, hi, k) for lo, hi, k in zip(lim.lower, lim.upper, n)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
            table = self.gravity_torque_exact(grid.reshape(-1, 3)).reshape(*grid.shape)
            step = np.array([a[1] - a[0] for a in axes])
            corners = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)])
            self._gravity = (table, lim.lower, step, np.array(n) - 2, corners)
        return self._gravity

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Gravity torques, trilinear in a 5° table over the crank range (the exact version takes 0.5 ms)."""
        table, lower, step, last, _ = self._gravity_table()
        # one crank triple each control step: scalar arithmetic, the eight corners by flat index
        idx, frac = [], []
        for v, lo, h, top in zip(np.asarray(q, float).tolist(), lower.tolist(), step.tolist(), last.tolist()):
            x = (v - lo) / h
            i = min(max(math.floor(x), 0), top)
            idx.append(i)
            frac.append(x - i)
        (fx, fy, fz), (i0, i1, i2) = frac, idx
        n1, n2 = table.shape[1], table.shape[2]
        a = (i0 * n1 + i1) * n2 + i2
        b, c = a + n2, a + n1 * n2
        gx, gy, gz = 1.0 - fx, 1.0 - fy, 1.0 - fz
        w = np.array([gx * gy * gz, gx * fy * gz, fx * gy * gz, fx * fy * gz, gx * gy * fz, gx * fy * fz,
                      fx * gy * fz, fx * fy * fz])
        return w @ table.reshape(-1, 3)[[a, b, c, c + n2, a + 1, b + 1, c + 1, c + n2 + 1]]

    def gravity_torques(self, qs: np.ndarray) -> np.ndarray:
        """:meth:`gravity_torque` for the rows of ``qs``, vectorised."""
        table, lower, step, last, corners = self._gravity_table()
        x = (np.atleast_2d(np.asarray(qs, float)) - lower) / step
        i = np.clip(np.floor(x).astype(int), 0, last)
        f = (x - i)[:, None, :]
        idx = i[:, None, :] + corners
        weights = np.prod(np.where(corners, f, 1.0 - f), axis=2)
        return np.einsum("nk,nkj->nj", weights, table[idx[..., 0], idx[..., 1], idx[..., 2]])


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("capaman", config=CapamanConfig, factory=CapamanRobot)
