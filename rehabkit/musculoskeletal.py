"""Public helpers for simulated-person plugins with a body: musculoskeletal arms (the catalogue, loading, scaling),
fitting them to a robot and its straps, static optimisation of muscle excitations, impairments (fatigue, tremor,
stretch reflex), and ``span`` (contiguous indices as a slice).

Each name loads its own module on first use (the arm models import MuJoCo).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

if TYPE_CHECKING:
    from rehabkit.musculo.fit import compose, fit_arm, strap_rows, strap_solref
    from rehabkit.musculo.human import CATALOGUE, PREFIX, HumanArm, load_arm_spec
    from rehabkit.musculo.impairments import MuscleFatigue, NoiseStream, StretchReflex, Tremor
    from rehabkit.musculo.scaling import scale_arm
    from rehabkit.musculo.static_opt import StaticOptimisation
    from rehabkit.numerics.indices import span

_FROM = {
    "rehabkit.musculo.fit": ("compose", "fit_arm", "strap_rows", "strap_solref"),
    "rehabkit.musculo.human": ("CATALOGUE", "PREFIX", "HumanArm", "load_arm_spec"),
    "rehabkit.musculo.impairments": ("MuscleFatigue", "NoiseStream", "StretchReflex", "Tremor"),
    "rehabkit.musculo.scaling": ("scale_arm",),
    "rehabkit.musculo.static_opt": ("StaticOptimisation",),
    "rehabkit.numerics.indices": ("span",),
}

__all__ = [
    "compose", "fit_arm", "strap_rows", "strap_solref", "CATALOGUE", "PREFIX", "HumanArm", "load_arm_spec",
    "MuscleFatigue", "NoiseStream", "StretchReflex", "Tremor", "scale_arm", "StaticOptimisation", "span",
]


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
