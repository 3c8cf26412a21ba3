"""Public helpers for plugins playing back a recorded session: reading a ROS bag (rosbag2 folder, ``.mcap``, ROS 1
``.bag``) into the session's joint states, wrench and targets, by role.

Each name loads its own module on first use (the bag reader imports ``rosbags`` when it reads).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rehabkit.bags.session_bag import BagError, SessionBag, read_session

_FROM = {
    "rehabkit.bags.session_bag": ("BagError", "SessionBag", "read_session"),
}

__all__ = [
    "BagError", "SessionBag", "read_session",
]


def __getattr__(name: str):
    for module, names in _FROM.items():
        if name in names:
            value = globals()[name] = getattr(importlib.import_module(module), name)
            return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
