"""Errors a run's setup raises for what can't be put together (a module of its own: cheap to import)."""

from __future__ import annotations

from typing import Any


class SetupError(RuntimeError):
    """The scenario is valid but its plugins can't be put together (message says why).

    ``breach`` is set (a :class:`rehabkit.core.limits.LimitBreach`) when the reason is a joint limit a plan
    would break.
    """

    def __init__(self, message: str, breach: Any = None):
        super().__init__(message)
        self.breach = breach
