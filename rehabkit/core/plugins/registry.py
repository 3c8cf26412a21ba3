"""The plugin registry: what discovery (:mod:`rehabkit.core.plugins.discovery`) found, imported on demand.

One entry-point group per kind — ``rehabkit.robots``, ``rehabkit.planners``, ``rehabkit.controllers``,
``rehabkit.sensors``, ``rehabkit.backends``, ``rehabkit.patients`` — and the entry point's name is the plugin's:
``[project.entry-points."rehabkit.planners"] min-jerk = "my_pkg.min_jerk"``. The module is imported when a
scenario names the plugin; its ``rehabkit_register_<kind>s`` hook registers it.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import traceback
from collections.abc import Callable, Iterable
from types import ModuleType
from typing import Any, Literal

import pluggy
from pydantic import BaseModel, ConfigDict, create_model

from rehabkit.core.kinds.names import suggest
from rehabkit.core.plugins import hookspecs
from rehabkit.core.plugins.discovery import Entry, installed_entries
from rehabkit.core.plugins.hookspecs import KINDS
from rehabkit.core.plugins.types import (
    BrokenPlugin,
    Declared,
    PluginConflictError,
    PluginError,
    PluginInfo,
    PluginLoadError,
    Provider,
    UnknownPluginError,
)

_NAME_RE = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")

__all__ = ["BrokenPlugin", "Entry", "PluginConflictError", "PluginError", "PluginInfo", "PluginLoadError",
           "PluginRegistry", "Provider", "Registrar", "UnknownPluginError", "default_registry", "load_plugins",
           "suggest"]


class Registrar:
    """What a registration hook receives: ``registry.add(name, config=..., factory=...)``."""

    def __init__(self, registry: PluginRegistry, kind: str):
        self._registry, self.kind = registry, kind

    def add(
        self,
        name: str,
        *,
        config: type[BaseModel],
        factory: Callable[..., Any],
        description: str | None = None,
        declared: Declared | None = None,
    ) -> None:
        """Register plugin ``name`` of this registrar's kind.

        Args:
            name: Lower-case, dash-separated ``type:`` key, e.g. ``"multi-cubic"``.
            config: Pydantic model of the plugin's settings (without a ``type`` field).
            factory: Callable ``(config, context) -> instance``; usually the class.
            description: One line; defaults to the factory docstring's first line.
            declared: What the plugin declares (``requires``, ``metrics``, a backend's ``real_person``) where the
                factory is a function; a class's own class attributes are read otherwise.
        """
        if not _NAME_RE.match(name):
            raise PluginError(f"{self.kind} name '{name}' must be lower-case words joined by '-'")
        if not (isinstance(config, type) and issubclass(config, BaseModel)):
            raise PluginError(f"{self.kind} '{name}': config must be a pydantic model class, got {config!r}")
        if "type" in config.model_fields:
            raise PluginError(f"{self.kind} '{name}': config must not declare 'type'; rehabkit adds it")
        if self.kind == "sensor" and "rate_hz" not in config.model_fields:
            raise PluginError(f"sensor '{name}': its config must derive from SensorConfig (rehabkit.plugin), which "
                              "holds the sensor's rate_hz")
        if not callable(factory):
            raise PluginError(f"{self.kind} '{name}': factory {factory!r} is not callable")
        if description is None:
            # the docstring's first paragraph, its lines joined (its first line alone stopped mid-sentence)
            paragraph = (getattr(factory, "__doc__", None) or "").strip().split("\n\n")[0]
            description = " ".join(line.strip() for line in paragraph.splitlines())
        typed = create_model(
            f"{config.__name__}",
            __base__=config,
            __module__=config.__module__,
            __doc__=config.__doc__,
            # (built now whatever its base defers: it is the model scenarios are validated with)
            __cls_kwargs__={"defer_build": False} if config.model_config.get("defer_build") else None,
            type=(Literal[name], ...),  # type: ignore[valid-type]
        )
        if config.model_config.get("extra") != "forbid" or not typed.__pydantic_complete__:
            # (a StrictModel forbids them already, and its subclass, built complete, takes its config as it is: made
            # again with the same config it would be the same model, at ~1 ms a plugin)
            typed.model_config = ConfigDict(**{**config.model_config, "extra": "forbid"})
            typed.model_rebuild(force=True)
        self._registry._staged.append(PluginInfo(self.kind, name, typed, factory, description.strip(),
                                                 self._registry._current, declared or Declared.of(factory)))


class PluginRegistry:
    """Installed plugins by kind and name, imported when first asked for (:meth:`get`).

    Discovery reads entry-point metadata only: ``names`` and the suggestions for unknown names come from it,
    and a broken or conflicting plugin costs nothing to runs that don't name it. :meth:`load_all` imports
    everything (``rehabkit plugins``, ``rehabkit schema``); what failed is in ``broken`` and ``conflicts``.
    """

    def __init__(self, entries: Iterable[Entry] = (), trace: bool = False):
        self.plugins: dict[str, dict[str, PluginInfo]] = {k: {} for k in KINDS}
        self.broken: list[BrokenPlugin] = []
        self._entries: dict[str, dict[str, list[Entry]]] = {k: {} for k in KINDS}
        for e in entries:
            self._entries[e.kind].setdefault(e.name, []).append(e)
        self._current = Provider("?", "?", "?")
        self._staged: list[PluginInfo] = []
        self._failed: dict[tuple[str, str], PluginLoadError] = {}
        self._pm = pluggy.PluginManager(hookspecs.PROJECT)
        self._pm.add_hookspecs(hookspecs)
        if trace:
            self._pm.trace.root.setwriter(lambda s: print(s, end="", file=sys.stderr))
            self._pm.enable_tracing()
        for kind in KINDS:
            getattr(self._pm.hook, f"rehabkit_register_{kind}s").call_historic(
                kwargs={"registry": Registrar(self, kind)})

    # -- registration ---------------------------------------------------------

    def _commit(self) -> list[PluginInfo]:
        staged, self._staged = self._staged, []
        for info in staged:
            rival = self.plugins[info.kind].get(info.name)
            others = [e.provider for e in self._entries[info.kind].get(info.name, [])
                      if e.provider.package != info.provider.package]
            if rival is not None or others:
                a = rival.provider if rival is not None else others[0]
                raise PluginConflictError(_conflict(info.kind, info.name, [a, info.provider]), info.kind, info.name,
                                          (a, info.provider))
        for info in staged:
            self.plugins[info.kind][info.name] = info
        return staged

    def register(self, obj: Any, provider: Provider) -> list[PluginInfo]:
        """Register an in-process plugin object (a module or namespace with hooks) now; what it registered.

        Raises:
            PluginConflictError: it registers a kind and name another package has.
        """
        self._current = provider
        name = f"{provider.package}:{provider.entry_point}"
        try:
            if self._pm.is_registered(obj):
                return []
            self._pm.register(obj, name=name)  # the historic hooks run here
            self._pm.check_pending()  # a misspelt hook name fails loudly
            return self._commit()
        except PluginConflictError:
            raise
        except Exception as exc:  # a broken plugin must not take the others down
            self._staged.clear()
            self.broken.append(BrokenPlugin(provider, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
            if self._pm.get_plugin(name) is not None:
                self._pm.unregister(name=name)
            raise PluginLoadError(f"{type(exc).__name__}: {exc}", provider, exc) from exc

    def _load(self, entry: Entry) -> PluginInfo:
        key = (entry.kind, entry.name)
        if key in self._failed:
            failed = self._failed[key]
            raise PluginLoadError(str(failed), failed.provider, failed.failure)
        p = entry.provider
        try:
            try:
                obj = entry.load()
            except Exception as exc:  # noqa: BLE001 (recorded: the others keep working)
                self.broken.append(BrokenPlugin(p, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
                raise PluginLoadError(f"{type(exc).__name__}: {exc}", p, exc) from exc
            self.register(obj, p)
            info = self.plugins[entry.kind].get(entry.name)
            if info is None or info.provider.package != p.package:
                made = [i.name for i in self.plugins[entry.kind].values() if i.provider == p] or "nothing"
                error = f"its entry point promises {entry.kind} '{entry.name}' but the module registered {made}"
                self.broken.append(BrokenPlugin(p, error, ""))
                raise PluginLoadError(error, p)
            return info
        except PluginError as exc:
            failure = exc.failure if isinstance(exc, PluginLoadError) else exc
            said = f"{exc} (package {p.package} {p.version}; fix or uninstall it)"
            self._failed[key] = PluginLoadError(said, p, failure)  # (said again, fields and all, if asked again)
            raise PluginLoadError(said, p, failure) from None

    # -- lookup ---------------------------------------------------------------

    def names(self, kind: str) -> list[str]:
        """Every installed plugin name of ``kind`` (from the metadata: nothing is imported)."""
        return sorted(set(self.plugins[kind]) | set(self._entries[kind]))

    def get(self, kind: str, name: str) -> PluginInfo:
        """The plugin ``name`` of ``kind``, imported on first use.

        Raises:
            UnknownPluginError: nothing of that name is installed (with the closest names).
            PluginConflictError: two packages install that name.
            PluginLoadError: its module failed to import or to register it.
        """
        info = self.plugins[kind].get(name)
        if info is not None:
            return info
        entries = self._entries[kind].get(name)
        if not entries:
            raise UnknownPluginError(kind, name, self.names(kind))
        if len({e.provider.package for e in entries}) > 1:
            providers = tuple(e.provider for e in entries)
            raise PluginConflictError(_conflict(kind, name, list(providers)), kind, name, providers)
        return self._load(entries[0])

    def find(self, kind: str, name: str) -> PluginInfo | None:
        """Like :meth:`get`, ``None`` where it would raise."""
        try:
            return self.get(kind, name)
        except PluginError:
            return None

    def load_all(self) -> list[str]:
        """Import every installed plugin; the conflicts found (the failures are in ``broken``)."""
        conflicts = []
        for kind in KINDS:
            for name in list(self._entries[kind]):
                try:
                    self.get(kind, name)
                except PluginConflictError as exc:
                    conflicts.append(str(exc))
                except PluginError:
                    pass
        return conflicts

    def all(self) -> list[PluginInfo]:
        """Every plugin that loaded (after :meth:`load_all`, all of them)."""
        return [info for kind in KINDS for info in sorted(self.plugins[kind].values(), key=lambda i: i.name)]


def _conflict(kind: str, name: str, providers: list[Provider]) -> str:
    who = " and by ".join(f"{p.package} {p.version} (entry point '{p.entry_point}')" for p in providers)
    return f"{kind} '{name}' is registered twice: by {who}; uninstall one of them or rename its plugin"


def load_plugins(
    extra: Iterable[tuple[ModuleType | object, Provider]] = (), trace: bool | None = None
) -> PluginRegistry:
    """The installed plugins (discovered from metadata, imported on demand) and ``extra`` in-process plugin
    objects, registered now (tests, notebooks).

    Args:
        extra: In-process plugin objects to register as well; a broken one is kept in ``broken``.
        trace: Print every hook call (default: the ``REHABKIT_TRACE_HOOKS`` env var).
    """
    registry = PluginRegistry(installed_entries(),
                              trace=bool(trace if trace is not None else os.environ.get("REHABKIT_TRACE_HOOKS")))
    for obj, provider in extra:
        with contextlib.suppress(PluginLoadError):  # kept in registry.broken
            registry.register(obj, provider)
    return registry


_DEFAULT: PluginRegistry | None = None


def default_registry() -> PluginRegistry:
    """The process-wide registry of installed plugins, discovered on first use."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = load_plugins()
    return _DEFAULT
