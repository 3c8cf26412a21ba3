"""Exact Dynamics ARM (MANUS), the wheelchair-mounted assistive manipulator (after Stuyt et al.).

Eight joints, in the order of ``q``: the optional vertical lift (25 cm), the six arm
joints and the gripper (opening of each of its two fingers). The arm's kinematics is
a PUMA-like modified-DH chain (Craig: α_{i-1}, a_{i-1}, d_i) from public MANUS
control code, in millimetres:

    1:   0°,   0,     0        4: +90°,   0,   323.4
    2: −90°,   0,     0        5: −90°,   0,     0
    3:   0°, 396.7,  99.2      6: +90°,   0,     0

Frame 6 is at the wrist centre; q3 = 0 holds the forearm perpendicular to the upper
arm (a 27.5 mm-radius cylinder). The gripper tip lies ``gripper`` metres along the
last axis; the lift slides the whole arm along the base z axis. Inverse kinematics is
closed form (``arm_kinematics``) and keeps the elbow up, as the ARM's controller does.
"""

from __future__ import annotations

from importlib import resources

import mujoco
import numpy as np
from pydantic import Field
from rehabkit_plugins.robots.arm_kinematics import elbow_up, nearest_elbow_up
from rehabkit_plugins.robots.contracts import LiftArmGripper

from rehabkit.kinematics import (
    ROBOT_CONAFFINITY,
    ROBOT_CONTYPE,
    DHRobotSpec,
    DHRowSpec,
    JointLimits,
    JointSpec,
    PoseSpec,
    RobotModel,
    SafeStop,
    build_dh_robot,
)
from rehabkit.plugin import Context, Robot, StrictModel, hookimpl, load_yaml

TABLE_MM = [(0, 0, 0), (-90, 0, 0), (0, 396.7, 99.2), (90, 0, 323.4), (-90, 0, 0), (90, 0, 0)]
FINGER = (0.006, 0.012, 0.035)  # finger half sizes [m]: thickness, width, length


class ArmConfig(StrictModel):
    """Placement beside the wheelchair, gripper length and whether the lift is fitted."""

    gripper: float = Field(0.12, gt=0.08, description="wrist centre to gripper tip [m]")
    lift: bool = Field(True, description="the optional 25 cm vertical lift under the arm")
    base: PoseSpec = Field(PoseSpec(position=(0.0, 0.0, 0.7)), description="arm base, beside the wheelchair seat")
    safe_stop: SafeStop = "hold"


def _add_fingers(xml: str, gripper: float, lift: bool) -> str:
    """Two fingers on the wrist link, the second mirroring the first through an equality constraint."""
    spec = mujoco.MjSpec.from_string(xml)
    hand = spec.body("j6_link")
    palm_end = gripper - 2 * FINGER[2]
    for geom in list(hand.geoms):  # the generated link runs to the tip; end the palm where the fingers start
        if geom.type == mujoco.mjtGeom.mjGEOM_CAPSULE:
            spec.delete(geom)
            hand.add_geom(name="palm", type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0, 0, palm_end],
                          size=[geom.size[0], 0, 0], contype=ROBOT_CONTYPE, conaffinity=ROBOT_CONAFFINITY,
                          rgba=list(geom.rgba), mass=0)
    for name, side in (("gripper", 1.0), ("gripper_mirror", -1.0)):
        finger = hand.add_body(name=f"{name}_finger", pos=[0, 0, gripper - FINGER[2]])
        finger.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[side, 0, 0], range=[0.0, 0.04],
                         limited=mujoco.mjtLimited.mjLIMITED_TRUE, damping=5.0)
        finger.add_geom(name=f"{name}_pad", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(FINGER),
                        pos=[side * FINGER[0], 0, 0], mass=0.05, contype=ROBOT_CONTYPE,
                        conaffinity=ROBOT_CONAFFINITY, rgba=[0.25, 0.25, 0.25, 1])
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="gripper_mirror", name2="gripper",
                      data=[0, 1, 0, 0, 0] + [0] * 7)
    spec.compile()
    return spec.to_xml()


class ArmRobot(Robot, LiftArmGripper):
    """Exact Dynamics ARM: lift + 6-DoF PUMA-like arm (MDH from MANUS code) + gripper; elbow-up IK."""

    def __init__(self, config: ArmConfig, context: Context | None = None):
        data = load_yaml(resources.files(__package__).joinpath("arm_joints.yaml").read_text())
        joints = [JointSpec.model_validate(j) for j in data["joints"]]
        table = [DHRowSpec(a=a / 1000, alpha_deg=alpha, d=d / 1000) for alpha, a, d in TABLE_MM]
        if config.lift:
            joints.insert(0, JointSpec.model_validate(data["lift"]))
            table.insert(0, DHRowSpec(joint="prismatic"))
        self.spec = DHRobotSpec(name="arm", convention="modified", table=table, joints=joints,
                                tool=PoseSpec(position=(0.0, 0.0, config.gripper)), base=config.base,
                                safe_stop=config.safe_stop)
        chain_model = build_dh_robot(self.spec)
        grip = JointSpec.model_validate(data["gripper"])
        g_lo, g_hi, g_v = grip.limits()
        cl = chain_model.limits
        limits = JointLimits(np.append(cl.lower, g_lo), np.append(cl.upper, g_hi), np.append(cl.velocity, g_v),
                             np.append(cl.effort, grip.effort))
        self.model = RobotModel(name="arm", mjcf=_add_fingers(chain_model.mjcf, config.gripper, config.lift),
                                joint_names=[*chain_model.joint_names, "gripper"], limits=limits,
                                ee_site=chain_model.ee_site, base_pose=chain_model.base_pose,
                                safe_stop=config.safe_stop, passive_joints=["gripper_mirror"])
        self.chain = self.spec.chain()
        self.config = config
        self.arm = slice(1, 7) if config.lift else slice(0, 6)  # the six arm joints within q
        self.lift_index = 0 if config.lift else None
        self.gripper_index = self.model.dof - 1

    def fk(self, q: np.ndarray) -> np.ndarray:
        return self.chain.fk(np.asarray(q, float)[: self.chain.dof])

    def fk_batch(self, qs: np.ndarray) -> np.ndarray:
        return self.chain.fk_batch(np.atleast_2d(qs)[:, : self.chain.dof])

    def elbow_up(self, q: np.ndarray) -> bool:
        """Whether the elbow sits above the shoulder–wrist line."""
        return elbow_up(*np.asarray(q, float)[self.arm][:3])

    def ik(self, pose: np.ndarray, reference: np.ndarray | None = None) -> list[np.ndarray]:
        """Elbow-up joint solutions reaching ``pose`` (base frame), nearest ``reference`` first.

        Lift and gripper keep their values in ``reference`` (default: lift down, gripper closed);
        each revolute angle is taken as the turn nearest the reference's within its range.
        """
        ref = np.zeros(self.model.dof) if reference is None else np.asarray(reference, float)
        lim = self.model.limits
        lift = ref[self.lift_index] if self.lift_index is not None else 0.0
        return list(nearest_elbow_up(np.asarray(pose, float), self.config.gripper, lift, ref, self.arm.start,
                                     lim.lower, lim.upper))


@hookimpl
def rehabkit_register_robots(registry) -> None:
    registry.add("arm", config=ArmConfig, factory=ArmRobot)
