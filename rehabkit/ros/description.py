"""A run's robot as ROS tools see it: ``/robot_description``, whose joint tree ``/tf`` and ``/tf_static`` carry
(:mod:`rehabkit.ros.tf_tree`).

``/robot_description`` is a URDF robot's own file (a ``.xacro`` expanded), else a URDF made from the model with the
robot's bodies as Pinocchio's model holds them (:func:`links`: each under its parent body — moved by a joint, or fixed
to it), and its joints, limits, link frames and inertias (no meshes).
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

AXES = {"RX": (1, 0, 0), "RY": (0, 1, 0), "RZ": (0, 0, 1), "PX": (1, 0, 0), "PY": (0, 1, 0), "PZ": (0, 0, 1)}


@dataclass(frozen=True)
class Link:
    """A body of the robot: its Pinocchio frame, and its parent's (None: a root, under the world); ``moving`` when a
    joint (``joint``, Pinocchio's index) lies between the two."""

    name: str
    frame: int
    parent: int | None
    joint: int

    @property
    def moving(self) -> bool:
        return self.joint > 0


def _is_body(frame) -> bool:
    return str(frame.type).endswith("BODY") and frame.name != "universe"


def links(model) -> list[Link]:
    """The robot's bodies, parents first (the model's frame order), each with its parent body."""
    out = []
    for fid, frame in enumerate(model.frames):
        if not _is_body(frame):
            continue
        p, seen = frame.parentFrame, {fid}
        while p > 0 and not _is_body(model.frames[p]) and p not in seen:
            seen.add(p)
            p = model.frames[p].parentFrame
        if p in seen:  # (a joint a reduced model locked can be its own parent frame: the last body before it)
            p = max((i for i in range(fid) if _is_body(model.frames[i]) and model.frames[i].parentJoint in
                     (frame.parentJoint, model.parents[frame.parentJoint])), default=0)
        parent = p if p > 0 and _is_body(model.frames[p]) else None
        above = model.frames[parent].parentJoint if parent is not None else 0
        out.append(Link(frame.name, fid, parent, frame.parentJoint if frame.parentJoint != above else 0))
    return out


def _origin(m) -> str:
    import pinocchio as pin

    xyz = " ".join(f"{v:.17g}" for v in m.translation)
    rpy = " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(m.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _joint_axis(joint) -> tuple[tuple[float, float, float], bool]:
    kind = joint.shortname().removeprefix("JointModel")
    if kind == "Mimic":  # (its axis: the motion it makes, which Pinocchio gives scaled by its multiplier)
        import numpy as np

        mimic = joint.extract()
        data = joint.createData()
        joint.calc(data, np.zeros(max(joint.idx_q + joint.nq, 1)))
        motion = np.asarray(data.S).ravel() / mimic.scaling
        prismatic = not np.any(motion[3:])
        axis = motion[:3] if prismatic else motion[3:]
        return (float(axis[0]), float(axis[1]), float(axis[2])), prismatic
    if kind in AXES:
        return AXES[kind], kind.startswith("P")
    if kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
        return tuple(joint.extract().axis), kind.startswith("Prismatic")
    raise ValueError(f"a {kind} joint has no URDF form here")


def _inertial(inertia) -> str:
    c, m = inertia.lever, inertia.inertia
    moments = " ".join(f'i{a}="{m[r, k]:.17g}"' for a, r, k in (("xx", 0, 0), ("xy", 0, 1), ("xz", 0, 2),
                                                              ("yy", 1, 1), ("yz", 1, 2), ("zz", 2, 2)))
    return (f'    <inertial><origin xyz="{c[0]:.17g} {c[1]:.17g} {c[2]:.17g}"/><mass value="{inertia.mass:.17g}"/>'
            f"<inertia {moments}/></inertial>")


def _fixed(parent: str, child: str, placement) -> list[str]:
    return [f'  <joint name={quoteattr(f"{parent}_to_{child}")} type="fixed">',
            f"    <parent link={quoteattr(parent)}/><child link={quoteattr(child)}/>", f"    {_origin(placement)}",
            "  </joint>"]


def urdf_from_model(model, name: str, limits=None) -> str:
    """A URDF of Pinocchio ``model`` with the links :func:`links` gives (revolute and prismatic joints, aligned or
    not; a joint's inertia on the link in its frame — the body it moves, or a link of the joint's own where the body
    sits elsewhere), its limits ``limits``' (a robot's ``JointLimits``: the model's own may be unbounded, which URDF
    cannot say)."""
    import pinocchio as pin

    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    tree = links(model)
    out = [f"<robot name={quoteattr(name)}>"]
    if any(link.parent is None and link.moving for link in tree):  # (a joint straight off the world)
        out.append('  <link name="base_link"/>')
    for link in tree:
        parent = model.frames[link.parent].name if link.parent is not None else "base_link"
        up = data.oMf[link.parent] if link.parent is not None else pin.SE3.Identity()
        if not link.moving:
            out += [f"  <link name={quoteattr(link.name)}/>"]
            if link.parent is not None:
                out += _fixed(parent, link.name, up.actInv(data.oMf[link.frame]))
            continue
        joint, j = model.joints[link.joint], link.joint
        try:
            axis, prismatic = _joint_axis(joint)
        except ValueError as exc:
            raise ValueError(f"joint {model.names[j]}: {exc}") from None
        at_joint = model.frames[link.frame].placement.isIdentity(1e-12)
        moved = link.name if at_joint else f"{model.names[j]}_frame"  # the link in the joint's frame
        out += [f"  <link name={quoteattr(moved)}>", _inertial(model.inertias[j]), "  </link>"]
        i, v = joint.idx_q, joint.idx_v
        lower, upper = (limits.lower[v], limits.upper[v]) if limits is not None else (
            model.lowerPositionLimit[i], model.upperPositionLimit[i])
        effort, speed = (limits.effort[v], limits.velocity[v]) if limits is not None else (
            model.effortLimit[v], model.velocityLimit[v])
        mimic = []
        if joint.shortname() == "JointModelMimic":  # (a joint coupled to another: URDF's <mimic>, its range the
            m = joint.extract()  # leader's mapped through the coupling)
            leader = next(k for k in range(1, model.njoints) if k != j and model.joints[k].idx_q == i
                          and model.joints[k].shortname() != "JointModelMimic")
            lower, upper = sorted((m.scaling * lower + m.offset, m.scaling * upper + m.offset))
            speed *= abs(m.scaling)
            mimic = [f'    <mimic joint={quoteattr(model.names[leader])} multiplier="{m.scaling:.17g}" '
                     f'offset="{m.offset:.17g}"/>']
        out += [f'  <joint name={quoteattr(model.names[j])} type="{"prismatic" if prismatic else "revolute"}">',
                f"    <parent link={quoteattr(parent)}/><child link={quoteattr(moved)}/>",
                f"    {_origin(up.actInv(data.oMi[j]))}",
                f'    <axis xyz="{axis[0]:.17g} {axis[1]:.17g} {axis[2]:.17g}"/>',
                f'    <limit lower="{lower:.17g}" upper="{upper:.17g}" effort="{effort:.17g}" '
                f'velocity="{speed:.17g}"/>', *mimic,
                "  </joint>"]
        if not at_joint:
            out += [f"  <link name={quoteattr(link.name)}/>"] + _fixed(moved, link.name,
                                                                    model.frames[link.frame].placement)
    out.append("</robot>")
    return "\n".join(out) + "\n"


def robot_description(robot, robot_section, resolve) -> str:
    """The URDF for ``/robot_description``: the robot's own file when the scenario names a URDF (a path or a
    ``package://`` URI; a ``.xacro`` expanded with its arguments), else made from its model."""
    from rehabkit.models.files.ros_package import resolve_uri

    file = getattr(robot_section, "file", None)
    if not isinstance(file, str) or not file.lower().endswith((".urdf", ".xacro")):
        return urdf_from_model(robot.model.pin_model, robot.model.name, robot.model.limits)
    packages = [resolve(p) for p in getattr(robot_section, "packages", [])]
    path = resolve_uri(file, resolve("."), packages, what="description") if "://" in file else resolve(file)
    if path.suffix == ".xacro":
        import xacro

        return xacro.process_file(str(path), mappings=dict(getattr(robot_section, "xacro_args", {}))).toxml()
    return path.read_text()
