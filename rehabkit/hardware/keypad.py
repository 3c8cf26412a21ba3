"""The bridge's keypad: keys typed at the robot (a line each on the bridge's standard input: ``e`` presses the
e-stop, ``c`` clears a latched one, ``a`` allows a new host to take a live session over), read without ever blocking
a tick."""

from __future__ import annotations

import os
import select
import time

KEYS = {"e": "estop", "estop": "estop", "c": "clear", "clear": "clear", "a": "allow", "allow": "allow"}


class Keypad:
    """Lines from a file descriptor (default: standard input), polled."""

    def __init__(self, fd: int = 0):
        self.fd, self._buffer, self.closed = fd, b"", False

    def poll(self) -> list[str]:
        """The keys typed since the last poll (``estop``/``clear``/``allow``; anything else is ignored)."""
        if self.closed or not select.select([self.fd], [], [], 0)[0]:
            return []
        data = os.read(self.fd, 4096)
        if not data:  # the keypad is gone (end of input): nothing more will come
            self.closed = True
        self._buffer += data
        *lines, self._buffer = self._buffer.split(b"\n")
        return [KEYS[k] for line in lines if (k := line.decode(errors="replace").strip().lower()) in KEYS]


def handle(bridge, keys: list[str], now: float) -> None:
    """Do what the keys say at the bridge, and say it (a line on standard output)."""
    for key in keys:
        if key == "estop":
            bridge.press_estop(now, "the e-stop key of the keypad at the robot", source="keypad")
            print("keypad: e-stop pressed, latched", flush=True)
        elif key == "allow":
            bridge.link.gate.allow(time.monotonic())
            print("keypad: a new host may take the session over (for 30 s)", flush=True)
        elif bridge.clear_estop("the keypad at the robot"):
            print("keypad: e-stop cleared; the next session ramps in", flush=True)
        else:
            print("keypad: e-stop not latched (nothing to clear)", flush=True)
