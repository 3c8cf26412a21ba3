"""A run's robot as ``/robot_description`` carries it: a URDF robot's own file as written, else a URDF made from the
robot's Pinocchio model (its joints, limits, link frames and inertias: what ``robot_state_publisher`` and a viewer's
robot model need; no meshes). Its link names are those the bag's ``/tf`` uses."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

AXES = {"RX": (1, 0, 0), "RY": (0, 1, 0), "RZ": (0, 0, 1), "PX": (1, 0, 0), "PY": (0, 1, 0), "PZ": (0, 0, 1)}


def link_names(model) -> list[str]:
    """The link each Pinocchio joint moves (its first body frame), the root as ``base_link`` when it has none."""
    names = ["base_link"] * model.njoints
    for frame in model.frames:
        if str(frame.type).endswith("BODY") and names[frame.parentJoint] == "base_link" and frame.parentJoint > 0:
            names[frame.parentJoint] = frame.name
    for j in range(1, model.njoints):  # (a joint without a body frame of its own: named after the joint)
        if names[j] == "base_link":
            names[j] = f"{model.names[j]}_link"
    return names


def _origin(m) -> str:
    import pinocchio as pin

    xyz = " ".join(f"{v:.17g}" for v in m.translation)
    rpy = " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(m.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def urdf_from_model(model, name: str, limits=None) -> str:
    """A URDF of Pinocchio ``model`` (revolute and prismatic joints, aligned or not), its limits ``limits``' (a
    robot's ``JointLimits``: the model's own may be unbounded, which URDF cannot say)."""
    links = link_names(model)
    out = [f"<robot name={quoteattr(name)}>", '  <link name="base_link"/>']
    for j in range(1, model.njoints):
        joint, inertia = model.joints[j], model.inertias[j]
        kind = joint.shortname().removeprefix("JointModel")
        if kind in AXES:
            axis, prismatic = AXES[kind], kind.startswith("P")
        elif kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
            axis, prismatic = tuple(joint.extract().axis), kind.startswith("Prismatic")
        else:
            raise ValueError(f"joint {model.names[j]}: a {kind} joint has no URDF form here")
        i, v = joint.idx_q, joint.idx_v
        lower, upper = (limits.lower[v], limits.upper[v]) if limits is not None else (
            model.lowerPositionLimit[i], model.upperPositionLimit[i])
        effort, speed = (limits.effort[v], limits.velocity[v]) if limits is not None else (
            model.effortLimit[v], model.velocityLimit[v])
        c, m = inertia.lever, inertia.inertia
        moments = " ".join(f'i{a}="{m[r, k]:.17g}"' for a, r, k in (("xx", 0, 0), ("xy", 0, 1), ("xz", 0, 2),
                                                                  ("yy", 1, 1), ("yz", 1, 2), ("zz", 2, 2)))
        out += [f"  <link name={quoteattr(links[j])}>",
                f'    <inertial><origin xyz="{c[0]:.17g} {c[1]:.17g} {c[2]:.17g}"/><mass value="{inertia.mass:.17g}"/>'
                f"<inertia {moments}/></inertial>", "  </link>",
                f'  <joint name={quoteattr(model.names[j])} type="{"prismatic" if prismatic else "revolute"}">',
                f"    <parent link={quoteattr(links[model.parents[j]])}/><child link={quoteattr(links[j])}/>",
                f"    {_origin(model.jointPlacements[j])}",
                f'    <axis xyz="{axis[0]:.17g} {axis[1]:.17g} {axis[2]:.17g}"/>',
                f'    <limit lower="{lower:.17g}" upper="{upper:.17g}" effort="{effort:.17g}" '
                f'velocity="{speed:.17g}"/>',
                "  </joint>"]
    out.append("</robot>")
    return "\n".join(out) + "\n"


def robot_description(robot, robot_section, resolve) -> str:
    """The URDF for ``/robot_description``: the robot's own file when the scenario names a ``.urdf``, else made from
    its model."""
    file = getattr(robot_section, "file", None)
    if isinstance(file, str) and file.lower().endswith(".urdf"):
        return Path(resolve(file)).read_text()
    return urdf_from_model(robot.model.pin_model, robot.model.name, robot.model.limits)
