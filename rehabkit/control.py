"""Public helpers for controllers: a prioritised QP task stack (whole-body control), a small SPD solve, learned
policies, and a store of saved poses (patches).

Each name loads its own module on first use (the task stack imports Pinocchio and SciPy).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rehabkit.models.policy import Policy
    from rehabkit.numerics.spd3 import adjugate_solve3
    from rehabkit.store.patches import Action, Patch, open_store
    from rehabkit.wholebody.stack import Level, compile_kernels, solve_cascade
    from rehabkit.wholebody.tasks import Constraints, ConstraintSpec, KinematicState, Task, TaskSpec

_FROM = {
    "rehabkit.wholebody.stack": ("Level", "compile_kernels", "solve_cascade"),
    "rehabkit.wholebody.tasks": ("Constraints", "ConstraintSpec", "KinematicState", "Task", "TaskSpec"),
    "rehabkit.numerics.spd3": ("adjugate_solve3",),
    "rehabkit.models.policy": ("Policy",),
    "rehabkit.store.patches": ("Action", "Patch", "open_store"),
}

__all__ = [
    "Level", "compile_kernels", "solve_cascade", "Constraints", "ConstraintSpec", "KinematicState", "Task",
    "TaskSpec", "adjugate_solve3", "Policy", "Action", "Patch", "open_store",
]


def __getattr__(name: str):
    for module, names in _FROM.items():
        if name in names:
            value = globals()[name] = getattr(importlib.import_module(module), name)
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
