"""Public helpers for workspace planners: a robot's voxel workspace (built, sampled) and the searches over it.

Each name loads its own module on first use (building a workspace imports SciPy).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

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


def __getattr__(name: str):
    for module, names in _FROM.items():
        if name in names:
            value = globals()[name] = getattr(importlib.import_module(module), name)
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
