"""Whole-body velocity control: tasks, constraints and the cascade of QPs."""
