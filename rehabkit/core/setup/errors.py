"""Errors a run's setup raises for what can't be put together (a module of its own: cheap to import)."""

from __future__ import annotations

import re
from typing import Any

from rehabkit.core.scenario.errors import Diagnostic, ScenarioError


class SetupError(RuntimeError):
    """The scenario is valid but its plugins can't be put together (message says why).

    ``breach`` is set (a :class:`rehabkit.core.setup.limits.LimitBreach`) when the reason is a joint limit a plan
    would break.
    """

    def __init__(self, message: str, breach: Any = None):
        super().__init__(message)
        self.breach = breach


class PluginSetupError(ScenarioError, SetupError):
    """A plugin refused its settings when it was built: located at the setting its message names (the first
    field of its config that the message mentions), else at its section. Both a :class:`ScenarioError` (the
    CLI's exit 2 with ``file:line:col``) and a :class:`SetupError`."""

    def __init__(self, source: Any, path: tuple[str, ...], fields: Any, message: str):
        named = [f for f in fields if re.search(rf"(?<![\w.-]){re.escape(f)}(?![\w-])", message)]
        at = next(((*path, f) for f in sorted(named, key=len, reverse=True) if (*path, f) in source.key_marks), path)
        mark = source.key_marks.get(at) or source.value_marks.get(path) or source.value_marks[()]
        ScenarioError.__init__(self, [Diagnostic(mark, ".".join(map(str, at)), message)])
        self.breach = None

    @classmethod
    def refused(cls, source: Any, path: tuple[str, ...], kind: str, config: Any, exc: Exception) -> PluginSetupError:
        """Plugin ``config.type`` of ``kind`` (its section at ``path``) refused with ``exc``: named once."""
        text = str(exc).removeprefix(f"{config.type}: ")  # plugins often name themselves
        return cls(source, path, type(config).model_fields, f"{kind} '{config.type}': {text}")
