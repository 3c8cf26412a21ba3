"""Public helpers for controllers: a prioritised QP task stack (whole-body control), a small SPD solve, learned
policies, and a store of saved poses (patches).

Each name loads its own module on first use (the task stack imports Pinocchio and SciPy).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

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


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
