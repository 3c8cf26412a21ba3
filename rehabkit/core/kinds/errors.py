"""Errors a plugin raises about its own settings and plans (a module of its own: the setup's error reporting imports it
without the plugin kinds)."""

from __future__ import annotations


class SettingError(ValueError):
    """A plugin refuses one of its settings when it is built: ``setting`` names it (a dotted path inside the
    plugin's section, as a string or a tuple: ``"kp"``, ``("voluntary", "strength_nm")``), ``problem`` says what is
    wrong with it, in the plugin's words. The run's setup reports it at that setting's line in the scenario file;
    any other ``ValueError`` a plugin raises is reported at the plugin's ``type``. With ``root`` the setting is the
    scenario's, from its top (``("rates", "control_hz")``): one the plugin's settings cannot live with."""

    def __init__(self, setting: str | tuple[str | int, ...], problem: str, root: bool = False):
        self.setting = tuple(setting.split(".")) if isinstance(setting, str) else tuple(setting)
        self.problem, self.root = problem, root
        super().__init__(f"{'.'.join(map(str, self.setting))}: {problem}")


class PlanningError(RuntimeError):
    """A planner could not produce a plan; the message says why. ``target``: the target it could not plan for,
    when it is one (the refusal of a run's first plan is then located where the scenario gives that target);
    ``setting``: the planner's setting that makes the plan impossible, when it is one (located there)."""

    def __init__(self, message: str, target: str | None = None, setting: str | tuple[str | int, ...] = ()):
        super().__init__(message)
        self.target = target
        self.setting = tuple(setting.split(".")) if isinstance(setting, str) else tuple(setting)
