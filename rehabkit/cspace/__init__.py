"""Configuration-space planning helpers: occupancy grids, joint matrices, clearance, path optimisation."""
