"""A plugin's fault during a run, said as a bug to report: which plugin, its package and version, what it did (raised,
or returned what does not fit), as the event's fields; with ``--debug`` (``REHABKIT_DEBUG=1``) its own traceback,
as a fault while it is built gives it."""

from __future__ import annotations

import os
import sys
import traceback

import numpy as np

NOTHING = object()  # (a call that returned nothing, not even None: it raised)


def debug_traceback(exc: BaseException) -> None:
    """The traceback behind a plugin's fault, on standard error, when asked for (``--debug``)."""
    if os.environ.get("REHABKIT_DEBUG"):
        traceback.print_exception(exc, file=sys.stderr)


def plugin_fault(registry, kind: str, name: str, exc: BaseException, returned=NOTHING,
                 expected: int = 0) -> tuple[str, dict]:
    """The message and fields of plugin ``name`` of ``kind`` failing with ``exc``: it raised it, or (``returned``
    given) it returned what does not fit ``expected`` values."""
    debug_traceback(exc)
    p = registry.get(kind, name).provider
    data = {"plugin": name, "kind": kind, "package": p.package, "version": p.version, "error": type(exc).__name__}
    who = f"{kind} '{name}' (package {p.package} {p.version})"
    if returned is not NOTHING:
        shape = list(np.shape(returned))
        return f"{who} returned {shape or 'a scalar'} where {expected} torques go (one per joint)", \
            {**data, "returned_shape": shape}
    return f"{who} raised {type(exc).__name__}: {exc}", data
