"""Sizing the arm model to the person: the upper arm and forearm stretched to the profile's segment lengths.

A segment is stretched along its own axis only (shoulder centre → elbow, elbow → wrist): every point of its bodies
— muscle attachment and via points, wrapping surfaces, the centre of mass, the next joint — moves along the axis
in proportion, while its distance from the axis, and so each muscle's moment arms about the joints, stays as it
was. Points beyond the wrist on a forearm body (MyoElbow's hand) move with the wrist. Bone meshes are stretched
along the body axis nearest to the segment's, and the transverse inertia by the square of the stretch.

A longer segment makes longer muscles: each muscle's length range (which sets its optimal fibre length in
MuJoCo's muscle model) is scaled by the ratio of its length after and before, at the model's reference posture,
so every muscle works at the same fraction of its optimal length as before. Force is unchanged.

Segment lengths, as the profile gives them: ``upper_arm`` from the shoulder centre to the elbow axis; ``forearm``
from the elbow axis to the middle of the hand's grip (as the L-Exos measures its forearm to the handle), taken
as the wrist centre plus :data:`GRIP_BEYOND_WRIST_M`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.musculo.human import ArmCatalogue

_RATIOS: dict[tuple, np.ndarray] = {}  # (model, lengths) → each muscle's length ratio, for scale_arm's memo
GRIP_BEYOND_WRIST_M = 0.07  # wrist centre to the middle of a closed hand's grip, adult [m]
SEGMENTS = {"myoarm": {"upper_arm": ("humerus_r",), "forearm": ("ulna_r", "radius_r")},
            "myoelbow": {"upper_arm": ("r_humerus",), "forearm": ("r_ulna_radius_hand",)}}


def _wrist_in(spec: mujoco.MjSpec, cat: ArmCatalogue, body) -> np.ndarray:
    """The wrist centre in ``body``'s frame (MyoArm: a child body's origin through the radius; MyoElbow: a site)."""
    site = spec.site(cat.wrist)
    if site is not None and site.parent.name == body.name:
        return np.asarray(site.pos, float)
    wrist = spec.body(cat.wrist)
    p, chain = np.asarray(wrist.pos, float), wrist.parent
    while chain.name != body.name:  # through the radius, whose frame is the ulna's turned by pronation (zero)
        p = _rotate(chain.quat, p) + np.asarray(chain.pos, float)
        chain = chain.parent
    return p


def _rotate(quat_wxyz, v: np.ndarray) -> np.ndarray:
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, np.asarray(v, float), np.asarray(quat_wxyz, float))
    return out


def segment_lengths(spec: mujoco.MjSpec, cat: ArmCatalogue) -> dict[str, float]:
    """The model's own upper arm and forearm (elbow to grip) [m]."""
    elbow = spec.body(cat.elbow_body)
    upper = float(np.linalg.norm(elbow.pos))
    return {"upper_arm": upper, "forearm": float(np.linalg.norm(_wrist_in(spec, cat, elbow))) + GRIP_BEYOND_WRIST_M}


def _stretch(p: np.ndarray, axis: np.ndarray, length: float, k: float) -> np.ndarray:
    """``p`` moved along ``axis``: stretched by ``k`` within [0, length], shifted with the segment's end beyond."""
    s = float(p @ axis)
    new = k * min(max(s, 0.0), length) + (s - length if s > length else 0.0) + (s if s < 0 else 0.0)
    return p + (new - s) * axis


def _stretch_body(spec: mujoco.MjSpec, body, axis: np.ndarray, length: float, k: float) -> None:
    for site in body.sites:
        site.pos = _stretch(np.asarray(site.pos, float), axis, length, k)
    for geom in body.geoms:
        geom.pos = _stretch(np.asarray(geom.pos, float), axis, length, k)
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH and geom.meshname:
            mesh = spec.mesh(geom.meshname)
            local = _rotate(_conj(geom.quat), axis)  # the segment's axis in the mesh's frame
            along = int(np.argmax(np.abs(local)))
            scale = np.array(mesh.scale, float)
            scale[along] *= k
            mesh.scale = scale
    if body.explicitinertial:
        body.ipos = _stretch(np.asarray(body.ipos, float), axis, length, k)
        local = _rotate(_conj(body.iquat), axis)
        along = int(np.argmax(np.abs(local)))
        inertia = np.asarray(body.inertia, float) * k**2
        inertia[along] /= k**2
        body.inertia = inertia
    for joint in body.joints:
        joint.pos = _stretch(np.asarray(joint.pos, float), axis, length, k)
    for child in body.bodies:
        child.pos = _stretch(np.asarray(child.pos, float), axis, length, k)


def _conj(q) -> np.ndarray:
    q = np.asarray(q, float)
    return np.array([q[0], -q[1], -q[2], -q[3]])


def scale_arm(spec: mujoco.MjSpec, cat: ArmCatalogue, lengths: dict[str, float], memo: str | None = None
              ) -> dict[str, float]:
    """Stretch the segments named in ``lengths`` to them [m], in place; returns the stretch of each. ``memo`` names
    the unscaled model (e.g. its file): the muscle lengths measured for it (two compilations) are kept in this
    process for the next arm of that model and those lengths (a learning environment's resets)."""
    own = segment_lengths(spec, cat)
    factors = {name: lengths[name] / own[name] for name in ("upper_arm", "forearm") if name in lengths}
    if not factors:
        return {}
    key = None if memo is None else (memo, tuple(sorted((k, round(v, 12)) for k, v in lengths.items())))
    ratios = _RATIOS.get(key)
    before = _muscle_lengths(spec) if ratios is None else None
    shoulder, elbow = spec.body(cat.shoulder_body), spec.body(cat.elbow_body)  # (each one's origin on its joint)
    for name, k in factors.items():
        if name == "upper_arm":
            vector = np.asarray(elbow.pos, float)
            axis, length = vector / np.linalg.norm(vector), float(np.linalg.norm(vector))
            _stretch_body(spec, shoulder, axis, length, k)
            continue
        # the forearm: elbow to wrist stretched so that elbow to grip is as asked (the hand keeps its size); each
        # forearm bone along its own axis, from its origin (the radius's is a centimetre from the elbow's)
        k_bone = (lengths["forearm"] - GRIP_BEYOND_WRIST_M) / float(np.linalg.norm(_wrist_in(spec, cat, elbow)))
        factors[name] = k_bone
        for body_name in SEGMENTS[cat.spec_name]["forearm"]:
            body = spec.body(body_name)
            wrist = _wrist_in(spec, cat, body)
            _stretch_body(spec, body, wrist / np.linalg.norm(wrist), float(np.linalg.norm(wrist)), k_bone)
    if ratios is None:
        ratios = _muscle_lengths(spec) / before
        if key is not None:
            _RATIOS[key] = ratios
    for actuator, ratio in zip(spec.actuators, ratios):
        actuator.lengthrange = np.asarray(actuator.lengthrange, float) * ratio
    return factors


def _muscle_lengths(spec: mujoco.MjSpec) -> np.ndarray:
    """Each actuator's length at the model's reference posture."""
    model = spec.copy().compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return data.actuator_length.copy()
