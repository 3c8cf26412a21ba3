"""Every hook a rehabkit plugin can implement.

A plugin is a module named by an entry point in the group of its kind
(``rehabkit.robots``, ``rehabkit.planners``, ``rehabkit.controllers``,
``rehabkit.sensors``, ``rehabkit.backends``, ``rehabkit.patients``), the entry
point's name being the plugin's; it is imported when a scenario names it. It
implements the hook of its kind below, which receives a *registrar* and calls
``registry.add(name, config=Model, factory=Class)``. Built-in plugins are
loaded the same way as third-party ones.

Minimal plugin module::

    from rehabkit.plugin import hookimpl

    @hookimpl
    def rehabkit_register_planners(registry):
        registry.add("min-jerk", config=MinJerkConfig, factory=MinJerkPlanner)

The hooks are *historic*: a plugin registered after the registry asked is
still called, once, which is how each registration is credited to the package
that made it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import pluggy


class Registrar(Protocol):
    """What a registration hook receives (:class:`rehabkit.core.plugins.registry.Registrar` implements it)."""

    kind: str

    def add(self, name: str, *, config: type, factory: Callable[..., Any], description: str | None = None) -> None:
        """Register plugin ``name`` of this registrar's kind."""
        ...

PROJECT = "rehabkit"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)

# ---------------------------------------------------------------------------
# Registration hooks: called once per plugin module, at load time.
# ---------------------------------------------------------------------------


@hookspec(historic=True)
def rehabkit_register_robots(registry: Registrar) -> None:
    """Register robot plugins: ``factory(config, context)`` returns a :class:`rehabkit.core.kinds.interfaces.Robot`."""


@hookspec(historic=True)
def rehabkit_register_planners(registry: Registrar) -> None:
    """Register planner plugins: ``factory(config, context)`` returns a :class:`~rehabkit.plugin.Planner`."""


@hookspec(historic=True)
def rehabkit_register_controllers(registry: Registrar) -> None:
    """Register controller plugins: ``factory(config, context)`` returns a
    :class:`rehabkit.core.kinds.interfaces.Controller`."""


@hookspec(historic=True)
def rehabkit_register_sensors(registry: Registrar) -> None:
    """Register sensor plugins: ``factory(config, context)`` returns a :class:`~rehabkit.plugin.Sensor`."""


@hookspec(historic=True)
def rehabkit_register_backends(registry: Registrar) -> None:
    """Register backend plugins: ``factory(config, context)`` returns a :class:`~rehabkit.plugin.Backend`."""


@hookspec(historic=True)
def rehabkit_register_patients(registry: Registrar) -> None:
    """Register simulated-patient plugins: ``factory(config, context)`` returns a
    :class:`rehabkit.core.kinds.interfaces.Patient` (a person's behaviour at the robot's joints, in simulation)."""


KINDS: tuple[str, ...] = ("robot", "planner", "controller", "sensor", "backend", "patient")
