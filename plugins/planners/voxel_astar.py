"""Workspace planner with optimal A* over the inner voxels."""

from __future__ import annotations

from rehabkit.plugin import hookimpl
from rehabkit.workspaces import VoxelPlanner, VoxelPlannerConfig, astar


class VoxelAStar(VoxelPlanner):
    """Operational-space path by optimal A* (h = ||x - x_g||) on the workspace look-up table."""

    name = "voxel-astar"

    def search(self, ws, start, goal):
        return astar(ws, start, goal)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("voxel-astar", config=VoxelPlannerConfig, factory=VoxelAStar)
