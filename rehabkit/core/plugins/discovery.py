"""Plugin discovery: the installed plugins as their packages' metadata names them, one entry-point group per kind
(``rehabkit.robots``, ``rehabkit.planners``, …), nothing imported."""

from __future__ import annotations

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
    known = _DISTRIBUTIONS.get(key) or _DISTRIBUTIONS.setdefault(key, (dist.metadata["Name"], dist.version))
    return Provider(*known, ep.name)


def installed_entries() -> list[Entry]:
    """Every plugin installed under the groups ``rehabkit.robots``, ``rehabkit.planners``, … (metadata only)."""
    out, seen = [], set()
    installed = metadata.entry_points()  # one scan of the installed distributions
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
