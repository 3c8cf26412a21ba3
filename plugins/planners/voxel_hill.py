"""Workspace planner with greedy hill climbing over the inner voxels."""

from __future__ import annotations

from rehabkit.plugin import hookimpl
from rehabkit.workspaces import VoxelPlanner, VoxelPlannerConfig, hill


class VoxelHill(VoxelPlanner):
    """Operational-space path by greedy hill climbing (f = ||x - x_g||); may get stuck, then fails or falls back."""

    name = "voxel-hill"

    def search(self, ws, start, goal):
        return hill(ws, start, goal)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("voxel-hill", config=VoxelPlannerConfig, factory=VoxelHill)
