"""COMAN, the compliant humanoid of IIT (after Mohammadi et al., psychotherapeutic juggling).

The model (``coman.xml``, converted from the public URDF by ``tools/coman_mjcf.py``;
credits in the file) has a free joint at the pelvis and 29 driven joints: waist 3,
arms 2×7, legs 2×6. The robot's "base frame" is its pelvis: ``fk`` gives the hand in
the pelvis frame, and ``base`` places the pelvis so that both feet stand flat on the
floor in the standing posture. Gravity compensation shares the weight between the
two feet (minimum-norm contact wrenches), since a standing humanoid's legs carry its
whole body.
"""

from __future__ import annotations

from importlib import resources
from typing import Literal

import mujoco
import numpy as np
import pinocchio as pin
from pydantic import Field
from scipy.linalg.lapack import dgesv

from rehabkit.kinematics import JointLimits, RobotModel, SafeStop, matrix_to_quat_wxyz, rpy_to_matrix
from rehabkit.plugin import Context, FloatingBase, Robot, StrictModel, hookimpl

VELOCITY_RAD_S = 4.0  # the URDF's velocity limit for every joint (marked there as not measured)
FEET = ("l_sole", "r_sole")
SOLE_GEOMS = ["LFoot_sole", "RFoot_sole"]

STANDING_DEG = {  # knees slightly bent, arms relaxed with the elbows bent forward
    "LHipSag": -11.5, "LKneeSag": 23.0, "LAnkSag": -11.5, "RHipSag": -11.5, "RKneeSag": 23.0, "RAnkSag": -11.5,
    "RShLat": -8.0, "LShLat": 8.0, "RElbj": -30.0, "LElbj": -30.0,
}


class ComanConfig(StrictModel):
    """Where COMAN stands and which hand is the end effector."""

    hand: Literal["r_hand", "l_hand"] = Field("r_hand", description="end-effector site (palm centre)")
    position: tuple[float, float] = Field((0.0, 0.0), description="pelvis x, y on the floor [m]")
    yaw_deg: float = Field(0.0, description="heading")
    safe_stop: SafeStop = "hold"


class ComanRobot(Robot, FloatingBase):
    """COMAN humanoid: floating pelvis, 29 joints, primitive geometry, feet in flat floor contact."""

    def __init__(self, config: ComanConfig, context: Context | None = None):
        xml = resources.files(__package__).joinpath("coman.xml").read_text()
        probe = mujoco.MjModel.from_xml_string(xml)
        names = [probe.joint(j).name for j in range(probe.njnt) if probe.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        lo, hi = probe.jnt_range[1:, 0].copy(), probe.jnt_range[1:, 1].copy()
        effort = probe.jnt_actfrcrange[1:, 1].copy()
        limits = JointLimits(lo, hi, np.full(len(names), VELOCITY_RAD_S), effort)
        self.standing = np.radians([STANDING_DEG.get(n, 0.0) for n in names])
        height = self._standing_height(probe, names)
        base = np.eye(4)
        base[:3, :3] = rpy_to_matrix([0.0, 0.0, np.radians(config.yaw_deg)])
        base[:3, 3] = [*config.position, height]
        self.model = RobotModel(name="coman", mjcf=xml, joint_names=names, limits=limits, ee_site=config.hand,
                                base_pose=base, safe_stop=config.safe_stop, passive_joints=["root"],
                                floating=True, support_geoms=SOLE_GEOMS)
        self.config = config
        self._floating: pin.Model | None = None

    def _standing_height(self, model: mujoco.MjModel, names: list[str]) -> float:
        """Pelvis height putting the lowest sole-box corner of the standing posture on the floor."""
        data = mujoco.MjData(model)
        for name, value in zip(names, self.standing):
            data.qpos[model.joint(name).qposadr[0]] = value
        mujoco.mj_forward(model, data)
        lowest = np.inf
        for g in SOLE_GEOMS:
            geom = data.geom(g)
            half = model.geom(g).size
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
            z = (corners @ geom.xmat.reshape(3, 3).T + geom.xpos)[:, 2]
            lowest = min(lowest, float(z.min()))
        return float(data.xpos[model.body("Waist").id][2] - lowest)

    @property
    def floating_model(self) -> pin.Model:
        """Pinocchio model with the free-flyer pelvis (q: x, y, z, qx, qy, qz, qw, then the joints)."""
        if self._floating is None:
            self._floating = self.model.mjcf_pin_model()
        return self._floating

    def pin_configuration(self, q: np.ndarray, base_position: np.ndarray | None = None,
                          base_quat_wxyz: np.ndarray | None = None) -> np.ndarray:
        """Full Pinocchio configuration from the joints and a pelvis pose (default: where it starts)."""
        pos = self.model.base_pose[:3, 3] if base_position is None else base_position
        if base_quat_wxyz is None:
            if getattr(self, "_start_wxyz", None) is None:
                self._start_wxyz = matrix_to_quat_wxyz(self.model.base_pose[:3, :3])
            base_quat_wxyz = self._start_wxyz
        return np.concatenate([pos, base_quat_wxyz[1:], base_quat_wxyz[:1], q])

    def support_torque(self, q_full: np.ndarray) -> np.ndarray:
        """Joint torques holding the whole robot still on both feet (weight shared by min-norm wrenches)."""
        model = self.floating_model
        data = self._support_data()
        tau = pin.computeGeneralizedGravity(model, data, q_full)  # RNEA(q, 0, 0)
        pin.computeJointJacobians(model, data, q_full)  # (a frame's Jacobian needs no frame placements)
        for i, rows in self._feet_rows:
            rows[:] = pin.getFrameJacobian(model, data, i, pin.LOCAL_WORLD_ALIGNED)
        # the unactuated pelvis rows must balance: J_c,baseᵀ f = τ_base; the minimum-norm wrenches by the normal
        # equations (two flat feet give a well-conditioned 6×6 system; lstsq's SVD cost 3x as much every cycle)
        a = self._jc_base_t
        _, _, x, info = dgesv(a @ a.T, tau[:6])  # LAPACK directly: numpy's solve costs 3x as much at 6x6
        f = a.T @ x if info == 0 else np.linalg.lstsq(a, tau[:6], rcond=None)[0]
        return tau[6:] - self._jc_joints_t @ f

    def _support_data(self):
        if getattr(self, "_sdata", None) is None:
            self._sdata = self.floating_model.createData()
            jc = np.zeros((6 * len(FEET), self.floating_model.nv))  # the feet's Jacobians, stacked
            self._feet_rows = [(self.floating_model.getFrameId(f), jc[6 * k : 6 * k + 6]) for k, f in enumerate(FEET)]
            self._jc_base_t, self._jc_joints_t = jc[:, :6].T, jc[:, 6:].T  # views, made once
        return self._sdata

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Standing on both feet with the pelvis at its starting orientation."""
        return self.support_torque(self.pin_configuration(np.asarray(q, float)))


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("coman", config=ComanConfig, factory=ComanRobot)
