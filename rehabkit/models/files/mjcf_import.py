"""Robots from model files (MJCF or URDF) as :class:`RobotModel`.

MuJoCo reads the file (it imports URDF too); the robot is re-rooted under one
jointless ``base`` body at the origin, because Pinocchio's MJCF parser drops
the root body's placement. Joint limits come from the file where it has them
(range, ``actuatorfrcrange``, motor ``ctrlrange``·gear, URDF velocity/effort)
and from the scenario's overrides otherwise; a joint left without a limit is
an error naming the joint and the key to add.
"""

from __future__ import annotations

import difflib
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
from pydantic import Field

from rehabkit.models.dh import PoseSpec
from rehabkit.models.files.engine_check import engine_agreement
from rehabkit.models.mjcf_builder import ROBOT_CONAFFINITY, ROBOT_CONTYPE
from rehabkit.models.robot_model import JointLimits, RobotModel, SafeStop
from rehabkit.models.strict import FilePath, StrictModel

_MOVABLE = {int(mujoco.mjtJoint.mjJNT_HINGE): "revolute", int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic"}


class LimitOverride(StrictModel):
    """Limits for one joint, replacing (or supplying) the file's. Revolute: degrees; prismatic: metres."""

    range_deg: tuple[float, float] | None = None
    range_m: tuple[float, float] | None = None
    velocity_deg_s: float | None = Field(None, gt=0)
    velocity_m_s: float | None = Field(None, gt=0)
    effort: float | None = Field(None, gt=0, description="torque [N·m] of a revolute joint, force [N] of a "
                                 "prismatic one")


class ModelFileConfig(StrictModel):
    """A robot from a model file (path relative to the scenario)."""

    file: FilePath
    ee_frame: str = Field(description="site or body that is the end effector")
    base: PoseSpec = Field(PoseSpec(), description="robot base in the world")
    limits: dict[str, LimitOverride] = Field({}, description="per-joint limits by joint name")
    default_velocity_deg_s: float | None = Field(None, gt=0, description="for joints whose file has no speed limit")
    default_effort: float | None = Field(None, gt=0, description="for joints whose file has no effort limit")
    safe_stop: SafeStop = "hold"
    floating: bool = Field(False, description="the root moves freely (a legged robot): a free joint at the root, "
                                              "base is where it starts")
    feet: list[str] = Field([], description="floating: the links (bodies) whose contact with the floor is support, "
                                            "not a collision")


ROOT_JOINT = "root"  # a floating robot's free joint (simulated and measured; Pinocchio's model locks it)


class ModelFileError(ValueError):
    """A model file that can't be a robot as configured: what is wrong (``problem``), ``setting`` names the plugin
    setting to change (None: the file itself) and ``fix`` how (if given: said after the problem)."""

    def __init__(self, message: str, setting: str | tuple | None = None, fix: str = ""):
        self.problem, self.said, self.setting, self.fix = message, message, setting, fix
        super().__init__(f"{message}; {fix}" if fix else message)


def _rerooted_xml(spec: mujoco.MjSpec, model_dir: Path, ee_frame: str, floating: bool = False,
                  feet: tuple[str, ...] = ()) -> tuple[str, str | None, list[str]]:
    """The robot under one jointless ``base`` body (with a free joint when ``floating``), the end-effector site;
    returns the XML, the free joint's name (None: fixed) and the feet's geoms (named where they were not)."""
    for key in ("meshdir", "texturedir"):  # assets must still resolve from a temporary copy
        current = getattr(spec, key) or ""
        setattr(spec, key, str((model_dir / current).resolve()))
    for geom in spec.geoms:  # as on every rehabkit robot: links meet the world, not each other
        if geom.contype or geom.conaffinity:
            geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY
    root = ET.fromstring(spec.to_xml())
    world = root.find("worldbody")
    if world is None:
        raise ValueError("the model has no <worldbody>")
    movable = [c for c in list(world) if c.tag in ("body", "geom", "site", "frame")]
    taken = {b.get("name") for b in root.iter("body")}
    base = ET.Element("body", {"name": "base" if "base" not in taken else "rehabkit_base"})  # the file's own stays
    free = None
    for child in movable:
        if child.tag == "body" and (own := child.find("freejoint")) is not None:
            if not floating:
                raise ModelFileError(f"body '{child.get('name')}' is free-floating: set floating: true (and its "
                                     "feet), or fix it to the world", "floating")
            child.remove(own)  # (the free joint goes to the base above it: the robot's one root)
            free = own.get("name")
        world.remove(child)
        base.append(child)
    world.insert(0, base)
    if floating:
        # (Pinocchio names frames after bodies and joints alike: the free joint's name must be neither's)
        taken = {e.get("name") for tag in ("joint", "freejoint", "body", "site") for e in root.iter(tag)}
        free = free or (ROOT_JOINT if ROOT_JOINT not in taken else f"rehabkit_{ROOT_JOINT}")
        base.insert(0, ET.Element("freejoint", {"name": free}))
    support = []
    bodies = {b.get("name"): b for b in root.iter("body")}
    for foot in feet:
        if foot not in bodies:
            links = ", ".join(sorted(n for n in bodies if n))
            raise ModelFileError(f"'{foot}' is not a link of the robot; links: {links}", "feet")
        for i, geom in enumerate(g for g in bodies[foot].findall("geom")):
            if geom.get("contype", "1") != "0" or geom.get("conaffinity", "1") != "0":
                geom.set("name", geom.get("name") or f"{foot}_foot_{i}")
                support.append(geom.get("name"))
    sites = {s.get("name") for s in root.iter("site")}
    if ee_frame not in sites:
        body = next((b for b in root.iter("body") if b.get("name") == ee_frame), None)
        if body is None:
            names = sorted(n for n in sites | {b.get("name") for b in root.iter("body")} if n)
            close = difflib.get_close_matches(ee_frame, names, n=3, cutoff=0.5)
            listed = f" (its sites and bodies: {', '.join(names)})"  # (after the fix, where there is one)
            mean = f"did you mean {' or '.join(repr(c) for c in close)}?{listed}" if close else ""
            raise ModelFileError(f"ee_frame '{ee_frame}' is neither a site nor a body of the file"
                                 + ("" if close else listed), "ee_frame", fix=mean)
        ET.SubElement(body, "site", {"name": f"{ee_frame}_ee", "size": "0.01"})
    return ET.tostring(root, encoding="unicode"), free, support


def _load_spec(path: Path) -> mujoco.MjSpec:
    """The file as an MjSpec. A URDF's fixed links are kept as bodies (MuJoCo would fuse them into their parents
    and lose their names, yet a tool link on a fixed joint is the usual end effector), unless the file has
    ``<mujoco>`` settings of its own."""
    text = path.read_text(encoding="utf-8", errors="replace")
    root = ET.fromstring(text) if path.suffix.lower() == ".urdf" else None
    if root is None or root.tag != "robot" or root.find("mujoco") is not None:
        return mujoco.MjSpec.from_file(str(path))
    ET.SubElement(ET.SubElement(root, "mujoco"), "compiler", {"fusestatic": "false", "meshdir": str(path.parent)})
    return mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))


def robot_from_file(
    path: Path,
    config: ModelFileConfig,
    file_velocity: dict[str, float] | None = None,
    file_effort: dict[str, float] | None = None,
) -> RobotModel:
    """Load ``path`` (MJCF or URDF) as a robot.

    Args:
        path: Model file.
        config: The plugin's settings.
        file_velocity: Speed limits the file format carries but MuJoCo drops (URDF), by joint.
        file_effort: Effort limits the same way.
    """
    if not path.exists():
        raise ValueError(f"model file not found: {path}")
    try:
        spec = _load_spec(path)
        model = spec.compile()
    except Exception as exc:  # MuJoCo's own message says what and where
        raise ValueError(f"MuJoCo cannot load {path}: {exc}") from None
    joints = [j for j in range(model.njnt) if int(model.jnt_type[j]) in _MOVABLE]
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(joints) + (len(free) if config.floating else 0) != model.njnt:
        raise ValueError(f"{path.name}: only hinge and slide joints are supported for robots (and a free root joint "
                         "with floating: true)")
    if config.feet and not config.floating:
        raise ModelFileError("feet go with floating: true (a fixed robot stands on its base)", "feet")
    # a joint coupled to another (a URDF's <mimic>, which MuJoCo imports as a joint equality) follows it: simulated and
    # measured, not driven
    followers = [int(model.eq_obj1id[e]) for e in range(model.neq)
                 if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[e] >= 0]
    joints = [j for j in joints if j not in followers]
    names = [model.joint(j).name for j in joints]
    unknown = sorted(set(config.limits) - set(names))
    if unknown:
        close = difflib.get_close_matches(unknown[0], names, n=1, cutoff=0.5)
        listed = f" (its joints: {', '.join(names)})"  # (after the fix, where there is one)
        raise ModelFileError(f"{path.name} has no joint '{unknown[0]}'" + ("" if close else listed),
                             setting=("limits", unknown[0]), fix=f"did you mean '{close[0]}'?{listed}" if close else "")
    motor_effort: dict[int, float] = {}
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and model.actuator_ctrllimited[a]:
            motor_effort[int(model.actuator_trnid[a, 0])] = float(np.abs(model.actuator_ctrlrange[a]).max()
                                                                  * abs(model.actuator_gear[a, 0]))
    lower, upper, vel, eff = [], [], [], []
    for j, name in zip(joints, names):
        revolute = _MOVABLE[int(model.jnt_type[j])] == "revolute"
        o = config.limits.get(name, LimitOverride())
        pairs = (("range_deg", "range_m"), ("velocity_deg_s", "velocity_m_s"))  # (each joint in its own unit)
        if wrong := [(m, deg) if revolute else (deg, m) for deg, m in pairs
                     if getattr(o, m if revolute else deg) is not None]:
            kind, other = ("revolute (degrees)", "prismatic") if revolute else ("prismatic (metres)", "revolute")
            raise ModelFileError(f"joint '{name}' is {kind}: {wrong[0][0]} is for a {other} joint",
                                 setting=("limits", name, wrong[0][0]), fix=f"write {wrong[0][1]} instead")
        rng = o.range_deg if revolute else o.range_m
        if rng is not None:
            lo, hi = np.radians(rng) if revolute else rng
        elif model.jnt_limited[j]:
            lo, hi = model.jnt_range[j]
        else:
            raise ModelFileError(f"joint '{name}' has no range in {path.name}",
                                 fix=f"add limits.{name}.range_{'deg' if revolute else 'm'}")
        v = o.velocity_deg_s if revolute else o.velocity_m_s
        if v is not None:
            v = np.radians(v) if revolute else v
        elif file_velocity and name in file_velocity and file_velocity[name] > 0:
            v = file_velocity[name]
        elif config.default_velocity_deg_s is not None:
            v = np.radians(config.default_velocity_deg_s)
        else:
            raise ModelFileError(f"joint '{name}' has no speed limit", fix=f"add limits.{name}.velocity_"
                                 f"{'deg_s' if revolute else 'm_s'} or default_velocity_deg_s")
        e = o.effort
        if e is None and model.jnt_actfrclimited[j]:
            e = float(np.abs(model.jnt_actfrcrange[j]).max())
        if e is None and file_effort and file_effort.get(name, 0) > 0:
            e = file_effort[name]
        if e is None:
            e = motor_effort.get(j, config.default_effort)
        if e is None:
            raise ModelFileError(f"joint '{name}' has no effort limit",
                                 fix=f"add limits.{name}.effort or default_effort")
        lower.append(float(lo))
        upper.append(float(hi))
        vel.append(float(v))
        eff.append(float(e))
    xml, root_joint, support = _rerooted_xml(spec, path.parent, config.ee_frame, config.floating, tuple(config.feet))
    named_site = _has_site(xml, config.ee_frame)
    site = config.ee_frame if named_site else f"{config.ee_frame}_ee"
    robot = RobotModel(
        name=spec.modelname or path.stem, mjcf=xml, joint_names=names,
        limits=JointLimits(*(np.array(v) for v in (lower, upper, vel, eff))), ee_site=site,
        base_pose=config.base.matrix(), safe_stop=config.safe_stop, ee_body=None if named_site else config.ee_frame,
        passive_joints=[model.joint(j).name for j in followers] + ([root_joint] if root_joint else []),
        floating=config.floating, support_geoms=support,
    )
    if not (check := engine_agreement(model, robot, config.ee_frame)).agree:
        raise ModelFileError(f"{path.name}: {check}")
    return robot


def _has_site(xml: str, name: str) -> bool:
    return any(s.get("name") == name for s in ET.fromstring(xml).iter("site"))
