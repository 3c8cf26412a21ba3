"""Grids that take seconds to build, kept on disk by their content (like the workspace tables).

A key is everything the grid is computed from — the scene's static obstacles, the robot's geometry as sampled
points, the grid's extent and resolution — hashed; the array is stored as ``<kind>-<hash>.npy`` under
``$REHABKIT_CACHE`` (default ``~/.cache/rehabkit``), written whole (temp file, then rename), and also kept in
memory for the process (a sweep's runs share it).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable

import numpy as np

from rehabkit.workspace.build import cache_dir

_MEMO: dict[str, np.ndarray] = {}
_MEMO_MAX = 8


def key_of(*parts: object) -> bytes:
    """Bytes identifying ``parts`` (arrays by their exact contents, anything else by its repr)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            h.update(str((p.dtype, p.shape)).encode())
            h.update(np.ascontiguousarray(p).tobytes())
        else:
            h.update(repr(p).encode())
        h.update(b"|")
    return h.digest()


def cached_array(kind: str, key: bytes, build: Callable[[], np.ndarray]) -> np.ndarray:
    """The array stored for ``key``, or ``build()`` stored and returned."""
    name = f"{kind}-{hashlib.sha256(key).hexdigest()[:24]}"
    if name in _MEMO:
        return _MEMO[name]
    path = cache_dir() / f"{name}.npy"
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError):  # not there yet, or unreadable: build it again
        arr = build()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{name}.{os.getpid()}.tmp.npy")
            np.save(tmp, arr, allow_pickle=False)
            tmp.replace(path)
        except OSError:
            pass  # a read-only cache: the array is still good for this process
    if len(_MEMO) >= _MEMO_MAX:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[name] = arr
    return arr
