"""Workspace planner with weighted (suboptimal, faster) A* over the inner voxels."""

from __future__ import annotations

from pydantic import Field

from rehabkit.plugin import hookimpl
from rehabkit.workspaces import VoxelPlanner, VoxelPlannerConfig, astar


class WeightedAStarConfig(VoxelPlannerConfig):
    """Weighted A*: the heuristic is amplified by ``weight``."""

    weight: float = Field(1.5, ge=1.0, description="h(x) = weight * ||x - x_g||")


class VoxelWeightedAStar(VoxelPlanner):
    """Operational-space path by weighted A* (h = 1.5 ||x - x_g||) on the workspace look-up table."""

    name = "voxel-wastar"

    def search(self, ws, start, goal):
        return astar(ws, start, goal, weight=self.config.weight)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("voxel-wastar", config=WeightedAStarConfig, factory=VoxelWeightedAStar)
