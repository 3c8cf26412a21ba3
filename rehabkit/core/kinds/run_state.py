"""What a plugin changes while a run goes, taken and put back: the contract behind a run session's snapshot.

A run session (:class:`~rehabkit.core.run.session.RunSession`) can be snapshotted at a step and restored — a
learning environment's reset, a replay forked at a time. The session's own state and the backend's are its
business; each plugin's is the plugin's, through two methods every kind but the robot has (:class:`RunState`):
``run_state()`` returns it, ``restore_run_state(state)`` puts it back.

The default suits most plugins with no code: it takes the plugin's own attributes — arrays and random generators
copied, numbers and flags, lists, dicts and sets copied element by element, any other object by reference (an
object the plugin replaces rather than changes, such as its settings). A plugin keeping state *inside* another
object it changes in place (a filter object, a solver warm start) overrides the two methods, or names those
attributes in ``RUN_STATE_NESTED`` so they are taken the same way, recursively; ``RUN_STATE_FIELDS`` narrows what is
taken to the attributes that change. Put into another run (a replay forked with other settings), a reference to one
of the first run's parts (its robot, backend, a sensor) is put back as the second run's counterpart.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

__all__ = ["RunState", "capture", "restore", "translating"]

_ATOMS = (type(None), bool, int, float, complex, str, bytes, np.generic)
_HASH = type(hashlib.sha256())  # a running digest (of the draws a stream made, say): copied
# while a snapshot is put into another run (a fork): the first run's parts (its robot, backend, sensors ...), by id,
# to the second's, so that a plugin's reference to one points to its counterpart
_TRANSLATE: ContextVar[dict[int, Any] | None] = ContextVar("rehabkit_run_state_translate", default=None)


@contextmanager
def translating(parts: dict[int, Any]) -> Iterator[None]:
    """Restore with references to one run's parts (``id(part) -> counterpart``) pointing to another's."""
    token = _TRANSLATE.set(parts)
    try:
        yield
    finally:
        _TRANSLATE.reset(token)


class _Generator:
    """A random generator's state, to be put back into the same generator (others may hold it: ``Context.rng``)."""

    __slots__ = ("state",)

    def __init__(self, gen: np.random.Generator):
        self.state = gen.bit_generator.state


class _Nested:
    """An object whose own state was taken: put back into the object, which is put back in its place."""

    __slots__ = ("obj", "state")

    def __init__(self, obj: Any, state: dict):
        self.obj, self.state = obj, state


class _Own(_Nested):
    """A part whose state its own ``run_state()`` took: put back by its ``restore_run_state``."""

    __slots__ = ()


def _take(value: Any) -> Any:
    if isinstance(value, _ATOMS):
        return value
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, np.random.Generator):
        return _Generator(value)
    if isinstance(value, list):
        return [_take(v) for v in value]
    if isinstance(value, dict):
        return {k: _take(v) for k, v in value.items()}
    if isinstance(value, set):
        return set(value)
    if isinstance(value, _HASH):
        return value.copy()
    return value  # tuples, frozen records, objects: by reference (replaced, not changed, while a run goes)


def _give(current: Any, saved: Any) -> Any:
    """The value to hold again: ``current`` changed in place where it is the same kind of container (whoever else
    holds it — a bound ``list.append``, a column view — sees the old contents again), else ``saved`` itself."""
    if isinstance(saved, _Generator):
        if isinstance(current, np.random.Generator):
            current.bit_generator.state = saved.state
            return current
        gen = np.random.default_rng()
        gen.bit_generator.state = saved.state
        return gen
    if isinstance(saved, _Nested):  # (into the part held now where it is of the same kind: a fork's own part)
        part = current if current is not None and type(current) is type(saved.obj) else saved.obj
        if isinstance(saved, _Own):
            part.restore_run_state(saved.state)
        else:
            restore(part, saved.state)
        return part
    if isinstance(saved, np.ndarray):
        if isinstance(current, np.ndarray) and current.shape == saved.shape and current.dtype == saved.dtype \
                and current.flags.writeable:
            current[...] = saved
            return current
        return saved.copy()
    if isinstance(saved, list):
        items = [_give(None, v) for v in saved]
        if isinstance(current, list):
            current[:] = items
            return current
        return items
    if isinstance(saved, dict):
        items = {k: _give(None, v) for k, v in saved.items()}
        if isinstance(current, dict):
            current.clear()
            current.update(items)
            return current
        return items
    if isinstance(saved, set):
        if isinstance(current, set):
            current.clear()
            current.update(saved)
            return current
        return set(saved)
    if isinstance(saved, _HASH):
        return saved.copy()
    parts = _TRANSLATE.get()
    return parts.get(id(saved), saved) if parts else saved


def capture(obj: Any, nested: tuple[str, ...] = ()) -> dict[str, Any]:
    """``obj``'s attributes as they are now (see the module docstring); those named in ``nested`` (or the object's
    ``RUN_STATE_NESTED``) are objects changed in place, taken recursively."""
    nested = nested or getattr(obj, "RUN_STATE_NESTED", ())
    only = getattr(obj, "RUN_STATE_FIELDS", None)  # (a class saying which of its attributes change while it runs)
    state = {}
    for name, value in vars(obj).items():
        if only is not None and name not in only:
            continue
        if name in nested and value is not None and hasattr(value, "run_state"):  # (a part with its own contract)
            state[name] = _Own(value, value.run_state())
        elif name in nested and value is not None and hasattr(value, "__dict__"):
            state[name] = _Nested(value, capture(value))
        else:
            state[name] = _take(value)
    return state


def restore(obj: Any, state: dict[str, Any]) -> None:
    """Put back what :func:`capture` took; attributes made since are left (a cache a plugin fills lazily)."""
    attrs = vars(obj)
    for name, saved in state.items():
        current = attrs.get(name)
        value = _give(current, saved)
        if value is not current:
            setattr(obj, name, value)


class RunState:
    """The run-state contract of a plugin kind (planner, controller, sensor, patient, backend): the default takes and
    puts back the plugin's own attributes (the module docstring says which, and when to override)."""

    RUN_STATE_NESTED: tuple[str, ...] = ()  # attributes holding objects the plugin changes in place
    RUN_STATE_FIELDS: tuple[str, ...] | None = None  # only these attributes change while it runs (None: all may)

    def run_state(self) -> Any:
        """What this plugin changes while a run goes, as it is now (a value :meth:`restore_run_state` takes)."""
        return capture(self)

    def restore_run_state(self, state: Any) -> None:
        """Stand again where :meth:`run_state` was taken."""
        restore(self, state)
