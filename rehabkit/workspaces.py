"""Public helpers for workspace planners: a robot's voxel workspace (built, sampled) and the searches over it.

Each name loads its own module on first use (building a workspace imports SciPy).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

if TYPE_CHECKING:
    from rehabkit.workspace.build import build_workspace
    from rehabkit.workspace.grid import VoxelWorkspace
    from rehabkit.workspace.planning import VoxelPlanner, VoxelPlannerConfig
    from rehabkit.workspace.sampling import random_inner, random_inner_not_straight
    from rehabkit.workspace.search import astar, beam, hill

_FROM = {
    "rehabkit.workspace.build": ("build_workspace",),
    "rehabkit.workspace.grid": ("VoxelWorkspace",),
    "rehabkit.workspace.sampling": ("random_inner", "random_inner_not_straight"),
    "rehabkit.workspace.planning": ("VoxelPlanner", "VoxelPlannerConfig"),
    "rehabkit.workspace.search": ("astar", "beam", "hill"),
}

__all__ = [
    "build_workspace", "VoxelWorkspace", "random_inner", "random_inner_not_straight", "VoxelPlanner",
    "VoxelPlannerConfig", "astar", "beam", "hill",
]


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
