"""What a plugin is to the registry: who provided it, its settings' model, what went wrong loading one."""

from __future__ import annotations

import re
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel

from rehabkit.core.kinds.names import suggest


class PluginError(Exception):
    """A plugin could not be registered or found."""


class PluginConflictError(PluginError):
    """Two packages registered the same ``kind`` and ``name``: ``providers``, both of them."""

    def __init__(self, message: str, kind: str = "", name: str = "", providers: tuple[Provider, ...] = ()):
        super().__init__(message)
        self.kind, self.name, self.providers = kind, name, tuple(providers)


class UnknownPluginError(PluginError):
    """A scenario named a plugin that is not installed."""

    def __init__(self, kind: str, name: str, available: list[str]):
        self.kind, self.name, self.available = kind, name, available
        super().__init__(f"unknown {kind} '{name}'{suggest(name, available)}")


@dataclass(frozen=True)
class Declared:
    """What a plugin declares as class attributes of its kind's base class, known before one is built:

    ``requires`` (capabilities it needs of the robot or backend), ``metrics`` (what its ``run_metrics`` reports,
    for ``expect:``), and of a backend ``real_person`` (it drives a real robot: a person in it is not simulated) and
    ``latch_name`` (its robot's e-stop latch's name on this machine, a template over ``robot`` and its settings)."""

    requires: tuple[type, ...] = ()
    metrics: tuple[Any, ...] = ()
    real_person: bool = False
    latch_name: str | None = None

    @classmethod
    def of(cls, factory: Callable[..., Any]) -> Declared:
        """The declarations of ``factory``: a plugin class's own or its base class's defaults; a factory function
        declares nothing."""
        if not isinstance(factory, type):
            return cls()
        return cls(tuple(getattr(factory, "requires", ())), tuple(getattr(factory, "metrics", ())),
                   bool(getattr(factory, "real_person", False)), getattr(factory, "latch_name", None))


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
        declared: What the plugin declares of itself (:class:`Declared`), read once when it registered.
    """

    kind: str
    name: str
    config: type[BaseModel]
    factory: Callable[..., Any]
    description: str
    provider: Provider
    declared: Declared = field(default_factory=lambda: Declared())

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


class PluginLoadError(PluginError):
    """A named plugin's module failed to import or to register what its entry point promised: ``provider`` the
    distribution that installed it (a :class:`Provider`, where known), ``failure`` what its module raised (the
    import's ``ModuleNotFoundError``, the registration's error; None where it imported and registered something
    else than its entry point promised)."""

    def __init__(self, message: str, provider: Provider | None = None, failure: BaseException | None = None):
        super().__init__(message)
        self.provider, self.failure = provider, failure
