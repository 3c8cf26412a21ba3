"""Workspace planner with the greedy 'beam' search, which keeps to the start-goal line."""

from __future__ import annotations

from pydantic import Field

from rehabkit.plugin import hookimpl
from rehabkit.workspaces import VoxelPlanner, VoxelPlannerConfig, beam


class BeamConfig(VoxelPlannerConfig):
    """Beam search: aims at the point ``k`` ahead of the current node on the line to the goal."""

    k: float = Field(0.05, gt=0, description="look-ahead along the line to the goal [m]")


class VoxelBeam(VoxelPlanner):
    """Operational-space path by greedy beam search (look-ahead k, default 5 cm); may get stuck."""

    name = "voxel-beam"

    def search(self, ws, start, goal):
        return beam(ws, start, goal, k=self.config.k)


@hookimpl
def rehabkit_register_planners(registry) -> None:
    registry.add("voxel-beam", config=BeamConfig, factory=VoxelBeam)
