"""The bridge's security log (IEC 81001-5-1's security events): every refused attempt on the link — a datagram or
handshake refused, with when, from where and why — written as it happens, one JSON line each, at most ``PER_S``
lines a second (a flood is summed up, not copied: the lines it would have made are counted by reason, and said in one
line when the budget allows again, or at the end).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

PER_S = 10  # lines a second at most, counted in each second of the wall clock (as the lines' "at" says it)


class SecurityLog:
    """Refused attempts, appended to ``path`` (owner-only, made so if new) as they happen, rate-limited."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        self._file = os.fdopen(fd, "a", buffering=1)  # (a line each: written as it happens)
        self._second, self._lines = None, 0  # the wall clock's second now, and the lines written in it
        self._last = 0.0  # when the newest line was written (time.time)
        self.suppressed: Counter = Counter()  # by reason, since the last line
        self.written = 0

    def refused(self, source: tuple | str, reason: str, now: float | None = None, **more) -> None:
        """One refused attempt from ``source`` (an address, or e.g. "keypad"), ``reason`` as counted; ``now``: the
        wall clock's time (``time.time``). At most ``PER_S`` lines in a second of it, the summing-up of what was
        left out included: a flood's first lines of each second, then (when the next second allows) one line
        summing up the rest; one line of each second is kept for the summing-up at the end (:meth:`close`)."""
        now = time.time() if now is None else now
        second = math.floor(now)
        if second != self._second:
            self._second, self._lines = second, 0
        if self._lines + (2 if self.suppressed else 1) > PER_S - 1:
            self.suppressed[reason] += 1
            return
        if self.suppressed:
            self._flush_suppressed(now)
        where = f"{source[0]}:{source[1]}" if isinstance(source, tuple) else source
        self._write({"at": _at(now), "source": where, "reason": reason, **more}, now)

    def note(self, event: str, **fields) -> None:
        """An event that is no refusal (a key reloaded, a session ended by it), never rate-limited."""
        self._file.write(json.dumps({"at": _at(time.time()), "event": event, **fields}) + "\n")
        self.written += 1

    def close(self) -> None:
        if self.suppressed:  # (in the second of the newest line, or a later one: its line was kept for this)
            self._flush_suppressed(max(time.time(), self._last))
        self._file.close()

    def _flush_suppressed(self, now: float) -> None:
        self._write({"at": _at(now), "suppressed": sum(self.suppressed.values()), "by_reason": dict(self.suppressed)},
                    now)
        self.suppressed.clear()

    def _write(self, record: dict, now: float) -> None:
        self._file.write(json.dumps(record) + "\n")
        self.written += 1
        self._lines += math.floor(now) == self._second
        self._last = now


def _at(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")
