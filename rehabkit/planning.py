"""Public helpers for planners: joint-space planning (OMPL seeds, scene collision checks, a genetic path optimiser
over a joint matrix and its occupancy), Cartesian obstacle avoidance around solids, and throwing (ballistics and
locally weighted regression).

Each name loads its own module on first use (OMPL, SciPy only where needed).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

if TYPE_CHECKING:
    from rehabkit.cspace.genetic import GAConfig, PathGA, resample
    from rehabkit.cspace.joint_matrix import JointMatrix, build_joint_matrix
    from rehabkit.cspace.occupancy import rasterise
    from rehabkit.cspace.ompl_seed import seed_ompl
    from rehabkit.cspace.scene_check import SceneCollision
    from rehabkit.geometry.box_avoid import NoPathError, plan_path
    from rehabkit.geometry.solids import Solid, make_solid
    from rehabkit.throwing.lwlr import LWLR
    from rehabkit.throwing.model import GRAVITY, PARAMS, Throw, follow_through, hand_path, parabola, plane_crossing

_FROM = {
    "rehabkit.cspace.genetic": ("GAConfig", "PathGA", "resample"),
    "rehabkit.cspace.joint_matrix": ("JointMatrix", "build_joint_matrix"),
    "rehabkit.cspace.occupancy": ("rasterise",),
    "rehabkit.cspace.ompl_seed": ("seed_ompl",),
    "rehabkit.cspace.scene_check": ("SceneCollision",),
    "rehabkit.geometry.box_avoid": ("NoPathError", "plan_path"),
    "rehabkit.geometry.solids": ("Solid", "make_solid"),
    "rehabkit.throwing.lwlr": ("LWLR",),
    "rehabkit.throwing.model": ("GRAVITY", "PARAMS", "Throw",
                                "follow_through", "hand_path", "parabola", "plane_crossing"),
}

__all__ = [
    "GAConfig", "PathGA", "resample", "JointMatrix", "build_joint_matrix", "rasterise", "seed_ompl",
    "SceneCollision", "NoPathError", "plan_path", "Solid", "make_solid", "LWLR", "GRAVITY", "PARAMS", "Throw",
    "follow_through", "hand_path", "parabola", "plane_crossing",
]


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
