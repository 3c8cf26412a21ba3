"""Errors a run's setup raises for what can't be put together (a module of its own: cheap to import)."""

from __future__ import annotations

from typing import Any

from rehabkit.core.kinds.errors import PlanningError, SettingError, apart, with_fix
from rehabkit.core.scenario.errors import Diagnostic, ScenarioError


class SetupError(RuntimeError):
    """The scenario is valid but its plugins can't be put together (message says why, ``fix`` how to go on where
    there is a way; said after the message).

    ``breach`` is set (a :class:`rehabkit.core.setup.limits.LimitBreach`) when the reason is a joint limit a plan
    would break. ``setting``: the scenario setting the refusal is about (``("patient",)``), where it names one,
    else ``()``.
    """

    fix = ""  # (a PluginSetupError's fixes are its diagnostics')
    setting: tuple = ()  # (a PluginSetupError's: the plugin's setting it is located at)

    def __init__(self, message: str, breach: Any = None, fix: str = "", setting: str | tuple = ()):
        super().__init__(with_fix(message, fix))
        self.breach, self.said, self.fix = breach, message, fix
        self.setting = tuple(setting.split(".")) if isinstance(setting, str) else tuple(setting)


class PluginSetupError(ScenarioError, SetupError):
    """A plugin refused its settings when it was built: located at the setting it names (a ``SettingError``'s
    ``setting``), else at its section's ``type``. Both a :class:`ScenarioError` (the CLI's exit 2 with
    ``file:line:col``) and a :class:`SetupError`. ``provider`` (a :class:`rehabkit.core.plugins.types.Provider`):
    the package whose plugin failed with a bug of its own while it was built (the one to report it to), else None.
    ``missing``: what each plugin needs that the robot or the backend lacks, ``{(kind, type): (capability, …)}``
    (the capability protocols of :mod:`rehabkit.core.kinds.capabilities`; the task's events that move objects under
    ``("task", "events")``), when that is why; else empty."""

    def __init__(self, source: Any, path: tuple[str, ...], message: str, setting: tuple = (), fix: str = "",
                 provider: Any = None):
        at = path
        for n in range(len(setting), 0, -1):  # the deepest part of the setting the file writes
            if (*path, *setting[:n]) in source.key_marks:
                at = (*path, *setting[:n])
                break
        else:
            at = (*path, "type") if setting == () and (*path, "type") in source.key_marks else path
        mark = source.key_marks.get(at) or source.value_marks.get(path) or source.value_marks[()]
        ScenarioError.__init__(self, [Diagnostic(mark, ".".join(map(str, at)), message, fix)])
        self.breach = None
        self.setting, self.provider = setting, provider
        self.missing: dict[tuple[str, str], tuple[type, ...]] = {}

    @classmethod
    def refused(cls, source: Any, path: tuple[str, ...], kind: str, config: Any, exc: Exception) -> PluginSetupError:
        """Plugin ``config.type`` of ``kind`` (its section at ``path``) refused with ``exc``: named once, located
        at the setting a :class:`SettingError` names; the error's fix (a field) kept the diagnostic's."""
        setting = exc.setting if isinstance(exc, (SettingError, PlanningError)) else ()
        if isinstance(exc, SettingError) and exc.root:  # (a scenario setting the plugin cannot live with)
            path = ()
        text, fix = apart(exc)
        text = text.removeprefix(f"{config.type}: ")  # plugins often name themselves
        if isinstance(exc, SettingError) and (*path, *setting) in source.key_marks:
            text = exc.problem  # (located at the setting, which the diagnostic names)
        return cls(source, path, f"{kind} '{config.type}': {text}", setting, fix)

    @classmethod
    def together(cls, errors: list[PluginSetupError]) -> PluginSetupError:
        """Several plugins' refusals as one error, each located (a user fixes them all at once)."""
        if len(errors) == 1:
            return errors[0]
        combined = cls.__new__(cls)
        ScenarioError.__init__(combined, [d for e in errors for d in e.diagnostics])
        combined.breach, combined.setting, combined.provider = None, (), None
        combined.missing = {k: v for e in errors for k, v in e.missing.items()}
        return combined
