"""Errors a plugin raises about its own settings and plans (a module of its own: the setup's error reporting imports it
without the plugin kinds)."""

from __future__ import annotations

from typing import Any


def with_fix(text: str, fix: str) -> str:
    """``text`` with its ``fix`` after it, as every error carrying a fix says the two (``text; fix``)."""
    return f"{text}; {fix}" if fix else text


def apart(exc: BaseException) -> tuple[str, str]:
    """An error's words and its fix, apart, read from its fields: ``said`` (its words without the fix) and ``fix``,
    where it carries both (the errors here do); else all its text and no fix — so a refusal that passes an error on
    keeps its fix a field."""
    fix, said = getattr(exc, "fix", ""), getattr(exc, "said", None)
    if isinstance(fix, str) and fix and isinstance(said, str):
        return said, fix
    return str(exc), ""


class SettingError(ValueError):
    """A plugin refuses one of its settings when it is built: ``setting`` names it (a dotted path inside the
    plugin's section, as a string or a tuple: ``"kp"``, ``("voluntary", "strength_nm")``), ``problem`` says what is
    wrong with it, in the plugin's words, and ``fix`` (if given) how to put it right. The run's setup reports it at
    that setting's line in the scenario file; any other ``ValueError`` a plugin raises is reported at the plugin's
    ``type``. With ``root`` the setting is the scenario's, from its top (``("rates", "control_hz")``): one the
    plugin's settings cannot live with. ``data``: the values the problem names (a DCF's commissioned node, a
    bus's load), where the plugin gives them: read as fields, not out of ``problem``'s words (empty if none)."""

    def __init__(self, setting: str | tuple[str | int, ...], problem: str, root: bool = False, fix: str = "",
                 data: dict[str, Any] | None = None):
        self.setting = tuple(setting.split(".")) if isinstance(setting, str) else tuple(setting)
        self.problem, self.root, self.fix = problem, root, fix
        self.data: dict[str, Any] = dict(data or {})
        self.said = f"{'.'.join(map(str, self.setting))}: {problem}"
        super().__init__(with_fix(self.said, fix))


class PlanningError(RuntimeError):
    """A planner could not produce a plan; the message says why, ``fix`` (if given) what would make one possible.
    ``target``: the target it could not plan for, when it is one (the refusal of a run's first plan is then located
    where the scenario gives that target); ``setting``: the planner's setting that makes the plan impossible, when
    it is one (located there); ``code``: why, as a code, where the planner gives one (a voxel search's
    ``no-arrival``, ``stuck``, …), else empty."""

    def __init__(self, message: str, target: str | None = None, setting: str | tuple[str | int, ...] = (),
                 fix: str = "", code: str = ""):
        super().__init__(with_fix(message, fix))
        self.target, self.said, self.fix = target, message, fix
        self.code = code  # (the cause as a field: read without parsing the message)
        self.setting = tuple(setting.split(".")) if isinstance(setting, str) else tuple(setting)
