"""Pinocchio and MuJoCo, built from the same model file, checked against each other before anything runs: the end
effector's position over postures spread through the joint ranges, and the total mass. A parser that reads the file
otherwise than the other (a site on a massless body placed elsewhere, a link's inertia dropped) is said at load,
not found in a run's numbers."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rehabkit.models.robot_model import RobotModel

POSTURES = 16  # spread through the ranges (a fixed seed): the check costs ~1 ms
TOLERANCE_M = 1e-6
MASS_TOLERANCE = 1e-5  # relative (Solo12's 2.5 kg differ by 2.8 mg between the two parsers)


@dataclass(frozen=True)
class EngineAgreement:
    """How far Pinocchio's and MuJoCo's models of one robot are apart: the end effector's largest distance [m] over
    the postures tried (``at``: the joints there [rad]) and each engine's total mass [kg]."""

    ee_frame: str
    distance_m: float
    at: np.ndarray
    mass_pinocchio: float
    mass_mujoco: float

    @property
    def mass_agrees(self) -> bool:
        return abs(self.mass_mujoco - self.mass_pinocchio) <= MASS_TOLERANCE * max(1.0, self.mass_mujoco)

    @property
    def agree(self) -> bool:
        return self.distance_m <= TOLERANCE_M and self.mass_agrees

    def __str__(self) -> str:
        said = []
        if self.distance_m > TOLERANCE_M:
            said.append(f"the end effector '{self.ee_frame}' {self.distance_m:.3g} m apart (at joints "
                        f"{np.round(np.degrees(self.at), 1).tolist()} deg)")
        if not self.mass_agrees:
            said.append(f"the mass {self.mass_pinocchio:.6g} kg in Pinocchio, {self.mass_mujoco:.6g} kg in MuJoCo (a "
                        "body whose inertia MuJoCo computes from its geoms, a mesh's for one, and Pinocchio's parser "
                        "otherwise: give that body an <inertial>)")
        return ("Pinocchio and MuJoCo read this model differently: " + "; ".join(said or ["nothing"])
                + " (the file's dynamics and kinematics must be one robot: report it with the file)")


def engine_agreement(mj: mujoco.MjModel, robot: RobotModel, ee_frame: str) -> EngineAgreement:
    """Pinocchio's model of ``robot`` against MuJoCo's model ``mj`` of the file it came from (the robot's base at the
    world's origin); joints not driven (followers, a free root) are held where Pinocchio locks them."""
    import pinocchio as pin

    model = robot.pin_model
    data, mjd = model.createData(), mujoco.MjData(mj)
    free = [j for j in range(mj.njnt) if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    addr = [int(mj.jnt_qposadr[mj.joint(name).id]) for name in robot.joint_names]
    site = mj.site(ee_frame).id if ee_frame in {mj.site(i).name for i in range(mj.nsite)} else None
    body = None if site is not None else mj.body(ee_frame).id
    lim = robot.limits
    qs = np.random.default_rng(0).uniform(np.maximum(lim.lower, -np.pi), np.minimum(lim.upper, np.pi),
                                          (POSTURES, robot.dof))
    worst, where = 0.0, qs[0]
    for q in qs:
        mjd.qpos[:] = 0.0
        for j in free:  # (at the origin, unturned: where Pinocchio's locked root is)
            mjd.qpos[mj.jnt_qposadr[j] + 3] = 1.0
        mjd.qpos[addr] = q
        mujoco.mj_kinematics(mj, mjd)
        theirs = mjd.site_xpos[site] if site is not None else mjd.xpos[body]
        pin.framesForwardKinematics(model, data, q)
        d = float(np.linalg.norm(data.oMf[robot.ee_frame_id].translation - theirs))
        if d > worst:
            worst, where = d, q
    return EngineAgreement(ee_frame, worst, where, float(sum(i.mass for i in model.inertias)),
                           float(mj.body_mass.sum()))
