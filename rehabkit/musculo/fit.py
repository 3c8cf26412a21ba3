"""Putting a person into the robot: their shoulder centre on the robot's, their arm on the robot's segments,
and soft straps between them.

At the start of a run (the robot at its start posture) :func:`fit_arm` moves the person's trunk so that the
glenohumeral centre meets the robot's shoulder point, then turns the arm's joints so that each strapped segment's
axis passes through its strap (least squares over the arm's joints within their ranges), and repeats: MyoArm's
shoulder centre moves with the elevation (the scapula follows the arm). Each strap then holds the point of the
person's segment that lies under it, so the straps start unloaded; where the person's joints and the robot's
are not aligned, moving the robot loads them, as on a real exoskeleton.

Straps are MuJoCo ``connect`` equalities made soft. MuJoCo sets a soft constraint's stiffness per unit of the
effective mass it acts on; :func:`strap_solref` turns a strap's stiffness [N/m] and damping [N·s/m] into those
terms from the effective mass at the start posture (so the figures hold there, and approximately elsewhere).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import least_squares

from rehabkit.models.chain import matrix_to_quat_wxyz
from rehabkit.models.wearable import Strap, Wearable
from rehabkit.musculo.human import PERSON_FROM_MODEL, PREFIX, HumanArm

STRAP_IMPEDANCE = 0.95  # MuJoCo's solimp d: constant, so a strap is a linear spring-damper
FIT_JOINTS = {"shoulder_plane": 0.0, "shoulder_elevation": 30.0, "shoulder_rotation": 0.0, "elbow_flexion": 60.0}
# (the joints the fit turns, and where it starts them [deg]: the arm a little forward, the elbow bent)


CUFF = "cuff_"  # a force-torque sensor named cuff_<segment> on a strap's body is that strap's cuff


def compose(spec: mujoco.MjSpec, arm_spec: mujoco.MjSpec, wearable: Wearable, base_pose: np.ndarray,
            straps: tuple[Strap, ...], segment_bodies: dict[str, str]) -> None:
    """Attach the arm (turned to face the robot's way) and one soft ``connect`` equality per strap."""
    rot = base_pose[:3, :3] @ wearable.person_axes() @ PERSON_FROM_MODEL
    frame = spec.worldbody.add_frame(pos=base_pose[:3, :3] @ np.asarray(wearable.shoulder) + base_pose[:3, 3],
                                     quat=matrix_to_quat_wxyz(rot))
    spec.attach(arm_spec, prefix=PREFIX, frame=frame)
    for strap in straps:
        if spec.body(strap.body) is None:
            bodies = sorted(b.name for b in spec.bodies if b.name and not b.name.startswith(PREFIX))
            raise ValueError(f"strap on the {strap.segment}: the robot has no body '{strap.body}'; its bodies: "
                             f"{', '.join(bodies)}")
        holder, anchor = strap.body, np.asarray(strap.position, float)
        cuff = spec.body(f"{CUFF}{strap.segment}")  # a force-torque sensor's mount: the strap is fastened to it
        if cuff is not None and cuff.parent.name == strap.body:
            holder, anchor = cuff.name, anchor - np.asarray(cuff.pos, float)
        spec.add_equality(type=mujoco.mjtEq.mjEQ_CONNECT, name=f"{PREFIX}strap_{strap.segment}",
                          name1=holder, name2=segment_bodies[strap.segment], objtype=mujoco.mjtObj.mjOBJ_BODY,
                          data=[*anchor, *([0.0] * 9)],
                          solimp=[STRAP_IMPEDANCE, STRAP_IMPEDANCE, 0.001, 0.5, 2.0])


def _roots(m: mujoco.MjModel) -> np.ndarray:
    return np.array([b for b in range(1, m.nbody) if m.body_parentid[b] == 0 and m.body(b).name.startswith(PREFIX)])


def fit_arm(arm: HumanArm, wearable: Wearable, base_pose: np.ndarray, straps: tuple[Strap, ...],
            strap_eqs: list[int], rounds: int = 3) -> tuple[dict[str, float], float]:
    """Place the trunk and pose the arm onto the robot as it stands in ``arm.data``; anchor the straps.

    Returns the fitted joint values [rad] and the largest distance from a strap to its segment's axis [m]
    after the fit (what the straps take up as the run starts).
    """
    m, d = arm.model, arm.data
    shoulder = base_pose[:3, :3] @ np.asarray(wearable.shoulder) + base_pose[:3, 3]
    roots = _roots(m)
    names = [n for n in FIT_JOINTS if n in arm.jnt]
    lo = np.array([m.jnt_range[arm.jnt[n], 0] for n in names])
    hi = np.array([m.jnt_range[arm.jnt[n], 1] for n in names])
    x = np.clip(np.radians([FIT_JOINTS[n] for n in names]), lo, hi)
    points = []
    for s in straps:
        body = m.body(s.body).id
        points.append((s.segment, body))

    def pose(values: np.ndarray) -> None:
        arm.set_pose(d.qpos, dict(zip(names, values)))
        mujoco.mj_kinematics(m, d)

    def residual(values: np.ndarray) -> np.ndarray:
        pose(values)
        out = []
        for (segment, body), s in zip(points, straps):
            p = d.xpos[body] + d.xmat[body].reshape(3, 3) @ np.asarray(s.position)
            a, b = arm.segment_line(segment)
            axis = (b - a) / np.linalg.norm(b - a)
            r = p - a
            out.append(r - (r @ axis) * axis)  # the strap's offset from the segment's axis
        out.append(0.002 * (values - x0))  # what the straps leave free (the upper arm's roll, straight) stays put
        return np.concatenate(out)

    x0 = x.copy()
    worst = 0.0
    for _ in range(rounds):
        pose(x)
        m.body_pos[roots] += shoulder - d.xpos[arm.body["shoulder"]]
        if names and straps:
            x = least_squares(residual, x, bounds=(lo, hi), xtol=1e-10, ftol=1e-10).x
    pose(x)
    for (segment, body), s, eq in zip(points, straps, strap_eqs):
        p = d.xpos[body] + d.xmat[body].reshape(3, 3) @ np.asarray(s.position)
        a, b = arm.segment_line(segment)
        axis = (b - a) / np.linalg.norm(b - a)
        worst = max(worst, float(np.linalg.norm((p - a) - ((p - a) @ axis) * axis)))
        human, holder = m.eq_obj2id[eq], m.eq_obj1id[eq]  # (the holder: the robot's body, or a cuff sensor's mount)
        m.eq_data[eq, 0:3] = d.xmat[holder].reshape(3, 3).T @ (p - d.xpos[holder])
        m.eq_data[eq, 3:6] = d.xmat[human].reshape(3, 3).T @ (p - d.xpos[human])  # the tissue under the strap
    return dict(zip(names, x)), worst


def strap_rows(d: mujoco.MjData, eq: int) -> slice:
    """The constraint rows of equality ``eq`` in the current step: MuJoCo puts the ``ne`` equality rows first, in
    the order of the equalities."""
    ids = d.efc_id[: d.ne]
    return slice(int(np.searchsorted(ids, eq, "left")), int(np.searchsorted(ids, eq, "right")))


def strap_solref(d: mujoco.MjData, eq: int, stiffness: float, damping: float) -> np.ndarray:
    """MuJoCo's direct ``solref`` (−k, −b) giving a strap of ``stiffness`` [N/m] and ``damping`` [N·s/m].

    With a constant impedance d, a strap loaded by a force f settles at a stretch r = f (1 − d) Â / k, Â being
    the constraint's inverse effective mass (MuJoCo's ``efc_diagA``): K = k / ((1 − d) Â), and likewise for the
    damping (checked against a known load in the tests).
    """
    rows = strap_rows(d, eq)
    inv_mass = float(np.mean(d.efc_diagA[rows]))
    scale = (1.0 - STRAP_IMPEDANCE) * inv_mass
    return np.array([-stiffness * scale, -damping * scale])
