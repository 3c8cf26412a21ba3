"""Public helpers for plugins playing back a recorded session: reading a ROS bag (rosbag2 folder, ``.mcap``, ROS 1
``.bag``) into the session's joint states, wrench and targets, by role.

Each name loads its own module on first use (the bag reader imports ``rosbags`` when it reads).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rehabkit.core.plugins.lazy import lazy_exports

if TYPE_CHECKING:
    from rehabkit.bags.session_bag import BagError, SessionBag, read_session

_FROM = {
    "rehabkit.bags.session_bag": ("BagError", "SessionBag", "read_session"),
}

__all__ = [
    "BagError", "SessionBag", "read_session",
]


__getattr__, __dir__ = lazy_exports(__name__, _FROM, __all__)
