"""Names re-exported by a module and loaded on first use: how the public helper modules (``rehabkit.kinematics``,
``rehabkit.planning``, …) give a plugin what it imports from them without importing what it does not use."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import Any


def lazy_exports(module: str, sources: Mapping[str, Iterable[str]],
                 names: Iterable[str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of module ``module`` (its ``__name__``) re-exporting ``sources`` (the module
    each name comes from → the names): a name's module is imported when the name is first asked for, and the name
    then kept in ``module`` (asked once); ``names``: its ``__all__``."""
    where = {name: source for source, found in sources.items() for name in found}
    namespace = vars(sys.modules[module])
    listed = set(names)

    def get(name: str) -> Any:
        if name not in where:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        value = namespace[name] = getattr(importlib.import_module(where[name]), name)
        return value

    def listing() -> list[str]:
        return sorted(set(namespace) | listed)

    return get, listing
