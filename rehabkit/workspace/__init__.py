"""Voxel workspace look-up tables: build, cache, query, search."""

from rehabkit.workspace.grid import BOUNDARY, INNER, UNREACHABLE, VoxelWorkspace

__all__ = ["VoxelWorkspace", "UNREACHABLE", "BOUNDARY", "INNER"]
