"""Plugin discovery (entry-point group ``rehabkit``) and the plugin registry."""

from __future__ import annotations

import difflib
import os
import re
import sys
import traceback
import typing
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib import metadata
from types import ModuleType
from typing import Any, Literal

import pluggy
from pydantic import BaseModel, ConfigDict, create_model

from rehabkit.core import hookspecs
from rehabkit.core.hookspecs import KINDS

ENTRY_POINT_GROUP = "rehabkit"
_NAME_RE = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")


class PluginError(Exception):
    """A plugin could not be registered or found."""


class PluginConflictError(PluginError):
    """Two packages registered the same kind and name."""


class UnknownPluginError(PluginError):
    """A scenario named a plugin that is not installed."""

    def __init__(self, kind: str, name: str, available: list[str]):
        self.kind, self.name, self.available = kind, name, available
        super().__init__(f"unknown {kind} '{name}'{suggest(name, available)}")


def suggest(name: str, candidates: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest candidates, or the list of choices."""
    candidates = sorted(candidates)
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.5)
    if close:
        return "; did you mean " + " or ".join(f"'{c}'" for c in close) + "?"
    return f"; choices: {', '.join(candidates)}" if candidates else ""


@dataclass(frozen=True)
class Provider:
    """The distribution that installed a plugin module."""

    package: str
    version: str
    entry_point: str


def _type_name(annotation: Any) -> str:
    """``list[float]``, ``Literal['a', 'b']``, ``PoseSpec``: how a field's type reads in a listing."""
    if typing.get_origin(annotation) is None and isinstance(annotation, type):
        return annotation.__name__
    return re.sub(r"\b(?:typing|[a-z_]+(?:\.[a-z_]+)*)\.([A-Za-z_]+)", r"\1", str(annotation))


@dataclass(frozen=True)
class PluginInfo:
    """One registered plugin.

    Attributes:
        kind: One of ``robot, planner, controller, sensor, backend``.
        name: The ``type:`` value scenarios use.
        config: Pydantic model validating its YAML section (with ``type`` added).
        factory: ``factory(config, context)`` builds the plugin instance.
        description: One line, from the argument or the factory's docstring.
        provider: Package that registered it.
    """

    kind: str
    name: str
    config: type[BaseModel]
    factory: Callable[..., Any]
    description: str
    provider: Provider

    def fields(self) -> list[tuple[str, str, str]]:
        """(name, type, default) for each config field except ``type``."""
        out = []
        for fname, f in self.config.model_fields.items():
            if fname == "type":
                continue
            ann = _type_name(f.annotation)
            default = "required" if f.is_required() else repr(f.get_default(call_default_factory=True))
            out.append((fname, ann, default))
        return out


@dataclass(frozen=True)
class BrokenPlugin:
    """An entry point that failed to load, with why."""

    provider: Provider
    error: str
    traceback: str


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
    ) -> None:
        """Register plugin ``name`` of this registrar's kind.

        Args:
            name: Lower-case, dash-separated ``type:`` key, e.g. ``"multi-cubic"``.
            config: Pydantic model of the plugin's settings (without a ``type`` field).
            factory: Callable ``(config, context) -> instance``; usually the class.
            description: One line; defaults to the factory docstring's first line.
        """
        if not _NAME_RE.match(name):
            raise PluginError(f"{self.kind} name '{name}' must be lower-case words joined by '-'")
        if not (isinstance(config, type) and issubclass(config, BaseModel)):
            raise PluginError(f"{self.kind} '{name}': config must be a pydantic model class, got {config!r}")
        if "type" in config.model_fields:
            raise PluginError(f"{self.kind} '{name}': config must not declare 'type'; rehabkit adds it")
        if not callable(factory):
            raise PluginError(f"{self.kind} '{name}': factory {factory!r} is not callable")
        if description is None:
            lines = (getattr(factory, "__doc__", None) or "").strip().splitlines()
            description = lines[0] if lines else ""
        typed = create_model(
            f"{config.__name__}",
            __base__=config,
            __module__=config.__module__,
            __doc__=config.__doc__,
            type=(Literal[name], ...),  # type: ignore[valid-type]
        )
        typed.model_config = ConfigDict(**{**config.model_config, "extra": "forbid"})
        typed.model_rebuild(force=True)
        self._registry._stage(PluginInfo(self.kind, name, typed, factory, description.strip(), self._registry._current))


@dataclass
class PluginRegistry:
    """Every loaded plugin, by kind and name, and the entry points that failed."""

    plugins: dict[str, dict[str, PluginInfo]] = field(default_factory=lambda: {k: {} for k in KINDS})
    broken: list[BrokenPlugin] = field(default_factory=list)
    _current: Provider = field(default=Provider("?", "?", "?"), repr=False)
    _staged: list[PluginInfo] = field(default_factory=list, repr=False)

    def _stage(self, info: PluginInfo) -> None:
        self._staged.append(info)

    def _commit(self) -> None:
        for info in self._staged:
            existing = self.plugins[info.kind].get(info.name)
            if existing is not None:
                self._staged.clear()
                a, b = existing.provider, info.provider
                raise PluginConflictError(
                    f"{info.kind} '{info.name}' is registered twice: by {a.package} {a.version} "
                    f"(entry point '{a.entry_point}') and by {b.package} {b.version} (entry point '{b.entry_point}'); "
                    f"uninstall one of them or rename its plugin"
                )
            self.plugins[info.kind][info.name] = info
        self._staged.clear()

    def names(self, kind: str) -> list[str]:
        return sorted(self.plugins[kind])

    def get(self, kind: str, name: str) -> PluginInfo:
        """The plugin ``name`` of ``kind``; :class:`UnknownPluginError` with suggestions if absent."""
        try:
            return self.plugins[kind][name]
        except KeyError:
            raise UnknownPluginError(kind, name, self.names(kind)) from None

    def all(self) -> list[PluginInfo]:
        return [info for kind in KINDS for info in self.plugins[kind].values()]


def _provider(ep: metadata.EntryPoint) -> Provider:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return Provider("?", "?", ep.name)
    return Provider(dist.metadata["Name"], dist.version, ep.name)


def load_plugins(
    extra: Iterable[tuple[ModuleType | object, Provider]] = (), trace: bool | None = None
) -> PluginRegistry:
    """Discover and register all plugins.

    Args:
        extra: In-process plugin objects to register as well (tests, notebooks).
        trace: Print every hook call (default: the ``REHABKIT_TRACE_HOOKS`` env var).
    """
    registry = PluginRegistry()
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)
    if trace if trace is not None else os.environ.get("REHABKIT_TRACE_HOOKS"):
        pm.trace.root.setwriter(lambda s: print(s, end="", file=sys.stderr))
        pm.enable_tracing()
    for kind in KINDS:
        getattr(pm.hook, f"rehabkit_register_{kind}s").call_historic(kwargs={"registry": Registrar(registry, kind)})

    seen: set[tuple[str, str]] = set()
    candidates: list[tuple[Callable[[], Any], Provider]] = []
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        key = (ep.name, ep.value)
        if key in seen:  # the same distribution visible twice on sys.path
            continue
        seen.add(key)
        candidates.append((ep.load, _provider(ep)))
    candidates += [((lambda obj=obj: obj), prov) for obj, prov in extra]

    for load, provider in candidates:
        registry._current = provider
        plugin_name = f"{provider.package}:{provider.entry_point}"
        try:
            pm.register(load(), name=plugin_name)  # historic hooks run here
            pm.check_pending()  # a misspelt hook name fails loudly
            registry._commit()
        except PluginConflictError:
            raise
        except Exception as exc:  # a broken plugin must not take the others down
            registry._staged.clear()
            registry.broken.append(BrokenPlugin(provider, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
            if pm.get_plugin(plugin_name) is not None:
                pm.unregister(name=plugin_name)
    return registry


_DEFAULT: PluginRegistry | None = None


def default_registry() -> PluginRegistry:
    """The process-wide registry of installed plugins, loaded on first use."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = load_plugins()
    return _DEFAULT
