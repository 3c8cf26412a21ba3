"""Convert the public COMAN URDF into rehabkit's MJCF model (run once; the output is committed).

    python tools/coman_mjcf.py PATH/TO/coman.urdf plugins/robots/coman.xml

The URDF (ADVRHumanoids/iit-coman-ros-pkg, coman_urdf/urdf/coman.urdf, commit 4ed4136, BSD-style
licence, (c) 2013 Enrico Mingo) references meshes that are not public here, so every link gets
primitive geometry sized to it: capsules from its joint to each child joint, the URDF's foot boxes,
a sphere for each soft hand, boxes for pelvis and chest. Masses, centres of mass and inertia tensors,
joint placements, axes (the tilted WaistLat axis included), limits and damping are the URDF's.
The head camera (Xtion) is left out; the soft hands and the IMU are welded to their parents. The
pelvis (Waist) gets a free joint; frames the controllers use become sites (soles, wrists, foot
corners, torso, and l_hand / r_hand at the palm centres).
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

SKIP = {"Xtion_body", "Xtion_cam_body", "gaze", "base_link"}
SITES = {"l_sole", "r_sole", "l_wrist", "r_wrist", "torso", "l_toe", "r_toe", "l_ankle", "r_ankle",
         "l_foot_upper_right_link", "l_foot_upper_left_link", "l_foot_lower_right_link", "l_foot_lower_left_link",
         "r_foot_upper_right_link", "r_foot_upper_left_link", "r_foot_lower_right_link", "r_foot_lower_left_link"}
RADIUS = [("Thigh", 0.045), ("HipMot", 0.045), ("LowLeg", 0.04), ("Footmot", 0.035), ("Sh", 0.035),
          ("Elb", 0.032), ("Forearm", 0.028), ("Wr", 0.025), ("DW", 0.05), ("Waist", 0.06)]
ARMATURE = 0.02  # reflected rotor inertia [kg·m²]: not in the URDF; a plausible value for COMAN's drives


def _vec(text: str | None, n: int = 3) -> np.ndarray:
    return np.array([float(x) for x in text.split()]) if text else np.zeros(n)


def _quat(rpy: np.ndarray) -> list[float]:
    x, y, z, w = Rotation.from_euler("xyz", rpy).as_quat()
    return [w, x, y, z]


def _radius(link: str) -> float:
    return next((r for key, r in RADIUS if key in link), 0.03)


def convert(urdf: Path) -> str:
    root = ET.parse(urdf).getroot()
    links = {link.get("name"): link for link in root.findall("link")}
    children: dict[str, list[ET.Element]] = {}
    for j in root.findall("joint"):
        children.setdefault(j.find("parent").get("link"), []).append(j)

    spec = mujoco.MjSpec()
    spec.modelname = "coman"
    spec.compiler.degree = False
    spec.compiler.autolimits = True

    def inertial(body, link: ET.Element) -> None:
        node = link.find("inertial")
        if node is None:
            return
        origin = node.find("origin")
        i = node.find("inertia").attrib
        body.explicitinertial = True
        body.mass = float(node.find("mass").get("value"))
        body.ipos = _vec(origin.get("xyz")) if origin is not None else np.zeros(3)
        body.iquat = _quat(_vec(origin.get("rpy"))) if origin is not None else [1, 0, 0, 0]
        body.fullinertia = [float(i[k]) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")]

    def geometry(body, name: str, link: ET.Element, child_points: list[np.ndarray]) -> None:
        box = link.find("collision/geometry/box")
        if box is not None:  # the feet: the URDF's own collision boxes
            origin = link.find("collision/origin")
            body.add_geom(name=f"{name}_sole", type=mujoco.mjtGeom.mjGEOM_BOX, size=_vec(box.get("size")) / 2,
                          pos=_vec(origin.get("xyz")), rgba=[0.2, 0.6, 0.7, 1], mass=0)
        r = _radius(name)
        for k, p in enumerate(child_points):
            if np.linalg.norm(p) > 0.01:
                body.add_geom(name=f"{name}_g{k}", type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, *p],
                              size=[r, 0, 0], rgba=[0.75, 0.75, 0.78, 1], mass=0)
        if name == "Waist":
            body.add_geom(name="pelvis", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.06, 0.09, 0.05],
                          pos=[-0.02, 0, 0.04], rgba=[0.75, 0.75, 0.78, 1], mass=0)
        if name == "DWYTorso":
            body.add_geom(name="chest", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.07, 0.1, 0.09],
                          pos=[-0.02, 0, 0.09], rgba=[0.75, 0.75, 0.78, 1], mass=0)
        if name.endswith("SoftHand"):
            body.add_site(name=f"{name[0].lower()}_hand", size=[0.01, 0, 0], rgba=[1, 0.5, 0, 1])
            body.add_geom(name=f"{name}_palm", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.035, 0, 0],
                          rgba=[0.3, 0.3, 0.3, 1], mass=0)

    def add(parent, name: str, joint: ET.Element | None) -> None:
        origin = joint.find("origin") if joint is not None else None
        pos = _vec(origin.get("xyz")) if origin is not None else np.zeros(3)
        rpy = _vec(origin.get("rpy")) if origin is not None else np.zeros(3)
        if name in SITES or (name not in links or links[name].find("inertial") is None) and joint is not None \
                and joint.get("type") == "fixed" and name not in ("Waist",):
            parent.add_site(name=name, pos=pos, quat=_quat(rpy), size=[0.01, 0, 0], rgba=[1, 0.5, 0, 1])
            for sub in children.get(name, []):  # frames hanging off a frame (foot corners off the sole)
                child = sub.find("child").get("link")
                if child in SITES:
                    sp = pos + Rotation.from_euler("xyz", rpy).apply(_vec(sub.find("origin").get("xyz")))
                    parent.add_site(name=child, pos=sp, size=[0.006, 0, 0], rgba=[1, 0.5, 0, 1])
            return
        body = parent.add_body(name=name, pos=pos, quat=_quat(rpy))
        if joint is None:
            body.add_freejoint(name="root")
        elif joint.get("type") == "revolute":
            lim, dyn = joint.find("limit"), joint.find("dynamics")
            body.add_joint(name=joint.get("name"), type=mujoco.mjtJoint.mjJNT_HINGE,
                           axis=_vec(joint.find("axis").get("xyz")),
                           range=[float(lim.get("lower")), float(lim.get("upper"))],
                           actfrcrange=[-float(lim.get("effort")), float(lim.get("effort"))],
                           damping=float(dyn.get("damping")) if dyn is not None else 0.0, armature=ARMATURE)
        inertial(body, links[name])
        points = [_vec(j.find("origin").get("xyz")) for j in children.get(name, [])
                  if j.find("child").get("link") not in SKIP and j.get("type") == "revolute"]
        geometry(body, name, links[name], points)
        for j in children.get(name, []):
            child = j.find("child").get("link")
            if child not in SKIP:
                add(body, child, j)

    add(spec.worldbody, "Waist", None)
    for geom in spec.geoms:  # touch the world, not each other (the capsules overlap at the joints by design)
        geom.contype, geom.conaffinity = 1, 0
    spec.compile()
    header = ("<!-- COMAN humanoid for rehabkit, converted by tools/coman_mjcf.py from the public URDF of\n"
              "     ADVRHumanoids/iit-coman-ros-pkg (coman_urdf/urdf/coman.urdf, commit 4ed4136; BSD-style licence,\n"
              "     (c) 2013 Enrico Mingo, Alessio Rocchi, IIT). Masses, inertias, joints and limits are the URDF's\n"
              "     (its velocity and effort limits are marked 'fake' there); the geometry is primitive shapes\n"
              "     sized to the links (the meshes are not public); joint armature is rehabkit's choice. -->\n")
    return header + spec.to_xml()


if __name__ == "__main__":
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    dst.write_text(convert(src))
    print(f"wrote {dst}")
