"""Plugin discovery: the installed plugins as their packages' metadata names them, one entry-point group per kind
(``rehabkit.robots``, ``rehabkit.planners``, …), nothing imported."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from typing import Any

from rehabkit.core.plugins.hookspecs import KINDS
from rehabkit.core.plugins.types import Provider

ENTRY_POINT_GROUP = "rehabkit"


@dataclass(frozen=True)
class Entry:
    """An installed plugin as its package's metadata names it: not imported until a scenario names it."""

    kind: str
    name: str
    load: Callable[[], Any]
    provider: Provider


_DISTRIBUTIONS: dict[str, tuple[str, str]] = {}  # (name, version) by dist-info folder


def _provider(ep: metadata.EntryPoint) -> Provider:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return Provider("?", "?", ep.name)
    key = str(getattr(dist, "_path", id(dist)))  # one Distribution per entry point; each read parses its file
    known = _DISTRIBUTIONS.get(key)
    if known is None:
        meta = dist.metadata  # (parsed once for both: ``dist.version`` is ``dist.metadata["Version"]``, parsed again)
        known = _DISTRIBUTIONS[key] = (meta["Name"], meta["Version"])
    return Provider(*known, ep.name)


_SCAN: tuple[tuple, Any] | None = None  # the last scan, and the search path it was made on


def installed_entry_points() -> Any:
    """Every installed distribution's entry points (``importlib.metadata.entry_points()``): the plugins' groups and
    the extensions' (:mod:`rehabkit.core.plugins.lifecycle`) read from one scan, which reads every distribution's
    metadata (~5 ms). Scanned again when the search path or a folder on it changed since (a distribution installed,
    removed or put on ``sys.path``)."""
    global _SCAN
    key = tuple((entry, _mtime(entry)) for entry in sys.path)
    if _SCAN is None or _SCAN[0] != key:
        _SCAN = (key, metadata.entry_points())
    return _SCAN[1]


def _mtime(entry: str) -> int | None:
    try:
        return os.stat(entry or ".").st_mtime_ns  # ('' is the working directory, as the import system reads it)
    except (OSError, TypeError, ValueError):
        return None


def installed_entries() -> list[Entry]:
    """Every plugin installed under the groups ``rehabkit.robots``, ``rehabkit.planners``, … (metadata only)."""
    out, seen = [], set()
    installed = installed_entry_points()  # one scan of the installed distributions
    for kind in KINDS:
        for ep in installed.select(group=group(kind)):
            key = (kind, ep.name, ep.value)
            if key in seen:  # the same distribution visible twice on sys.path
                continue
            seen.add(key)
            out.append(Entry(kind, ep.name, ep.load, _provider(ep)))
    return out


def group(kind: str) -> str:
    """The entry-point group of a plugin kind: ``rehabkit.planners`` for planners."""
    return f"{ENTRY_POINT_GROUP}.{kind}s"
