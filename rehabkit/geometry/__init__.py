"""Solid primitives with exact segment tests, and the deterministic box-avoid path planner."""
