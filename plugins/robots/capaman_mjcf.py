"""CaPaMan's MJCF: the whole mechanism in one tree, its loops closed by site-to-site ``connect`` equalities.

Per leg a crank (actuated hinge ``alpha_k``), a coupler hinged to it, a slider on
the coupler's bar, and a follower hinged to the base; the plate hangs from leg 1's
slider by a ball joint at H_1. Equalities close the loops: coupler end = follower
tip (each parallelogram), slider_k = plate joint H_k (legs 2 and 3).
"""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.kinematics import ROBOT_CONAFFINITY, ROBOT_CONTYPE, matrix_to_quat_wxyz

from .capaman_kinematics import CapamanGeometry

GREY, BLUE, ORANGE = [0.35, 0.35, 0.38, 1], [0.3, 0.5, 0.85, 1], [0.9, 0.55, 0.2, 1]
# link masses [kg] (plausible for the aluminium prototype), shared by the MJCF and the gravity model
MASS = {"crank": 0.08, "coupler": 0.12, "bar": 0.05, "slider": 0.03, "follower": 0.08, "tool": 0.05}


def _frame(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.column_stack([x, y, np.cross(x, y)])


def build_capaman_mjcf(geo: CapamanGeometry, crank_range_deg: tuple[float, float], plate_mass: float,
                       tool: tuple[float, float, float], tool_radius: float) -> str:
    """The MJCF text of the mechanism (link masses :data:`MASS`; the tool tip in the plate frame [m])."""
    spec = mujoco.MjSpec()
    spec.modelname = "capaman"
    spec.compiler.degree = False
    geom = dict(contype=ROBOT_CONTYPE, conaffinity=ROBOT_CONAFFINITY)

    def rod(body, name: str, start, end, mass: float, rgba, radius: float = 0.007) -> None:
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*start, *end],
            size=[radius, 0, 0],
            mass=mass,
            rgba=rgba,
            **geom,
        )

    base = spec.worldbody.add_body(name="base")
    base.add_geom(
        name="fixed_plate",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[geo.r_base + 0.05, geo.base_height / 2, 0],
        pos=[0, 0, geo.base_height / 2],
        rgba=GREY,
        **geom,
    )
    z = np.array([0.0, 0.0, 1.0])
    along, up = [0.0, 0.0, 0.0], [geo.b, 0.0, 0.0]
    sliders = []
    for k in range(3):
        n = k + 1
        t, o = geo.tangent[k], geo.centres[k]
        leg = matrix_to_quat_wxyz(_frame(t, z))  # x along the frame link, y up, z = e (normal to the leg plane)
        p1, p2 = o - 0.5 * geo.a * t, o + 0.5 * geo.a * t
        rod(base, f"frame_{n}", p1, p2, 0.0, GREY, radius=0.008)
        crank = base.add_body(name=f"crank_{n}", pos=p1, quat=leg)
        crank.add_joint(
            name=f"alpha_{n}",
            axis=[0, 0, 1],
            range=np.radians(crank_range_deg),
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            armature=0.02,
            damping=0.05,
        )
        rod(crank, f"crank_{n}", along, up, MASS["crank"], ORANGE)
        coupler = crank.add_body(name=f"coupler_{n}", pos=[geo.b, 0, 0])
        coupler.add_joint(name=f"coupler_{n}", axis=[0, 0, 1])
        rod(coupler, f"coupler_{n}", along, [geo.a, 0, 0], MASS["coupler"], BLUE)
        rod(coupler, f"bar_{n}", [geo.a / 2, 0, 0], [geo.a / 2, geo.h, 0], MASS["bar"], BLUE)
        coupler.add_site(name=f"coupler_end_{n}", pos=[geo.a, 0, 0], size=[0.004, 0, 0])
        slider = coupler.add_body(name=f"slider_{n}", pos=[geo.a / 2, geo.h, 0])
        slider.add_joint(name=f"slide_{n}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
        slider.add_geom(
            name=f"slider_{n}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.01, 0.01, 0.015],
            mass=MASS["slider"],
            rgba=ORANGE,
            contype=0,
            conaffinity=0,
        )
        slider.add_site(name=f"slider_{n}", size=[0.004, 0, 0])
        follower = base.add_body(name=f"follower_{n}", pos=p2, quat=leg)
        follower.add_joint(name=f"follower_{n}", axis=[0, 0, 1])
        rod(follower, f"follower_{n}", along, up, MASS["follower"], ORANGE)
        follower.add_site(name=f"follower_tip_{n}", pos=up, size=[0.004, 0, 0])
        sliders.append(slider)
    # the plate: origin at its centre, hanging from slider 1 by a ball joint at H_1; level at identity
    c = geo.plate_points
    in_leg1 = _frame(geo.tangent[0], z).T
    plate = sliders[0].add_body(name="plate", pos=in_leg1 @ (-c[0]), quat=matrix_to_quat_wxyz(in_leg1))
    plate.add_joint(name="plate_ball", type=mujoco.mjtJoint.mjJNT_BALL, pos=c[0])
    plate.add_geom(
        name="movable_plate",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[geo.r_plate + 0.015, 0.006, 0],
        mass=plate_mass,
        rgba=GREY,
        **geom,
    )
    tip = np.asarray(tool)
    rod(plate, "tool", [0, 0, 0.006], tip, MASS["tool"], [0.2, 0.8, 0.3, 1], radius=tool_radius)
    plate.add_site(name="tool_tip", pos=tip, size=[0.006, 0, 0])
    for k in (1, 2):
        plate.add_site(name=f"plate_joint_{k + 1}", pos=c[k], size=[0.004, 0, 0])
    connect = dict(type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE, solref=[0.002, 1.0])
    for k in range(3):
        spec.add_equality(
            name=f"parallelogram_{k + 1}", name1=f"coupler_end_{k + 1}", name2=f"follower_tip_{k + 1}", **connect
        )
    for k in (1, 2):
        spec.add_equality(name=f"spherical_{k + 1}", name1=f"slider_{k + 1}", name2=f"plate_joint_{k + 1}", **connect)
    spec.compile()
    return spec.to_xml()
