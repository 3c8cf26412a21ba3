"""The bridge's security log (IEC 81001-5-1's security events): every refused attempt on the link — a datagram or
handshake refused, with when, from where and why — written as it happens, one JSON line each, at most ``PER_S``
lines a second (a flood is summed up, not copied: the lines it would have made are counted by reason, and said in one
line when the budget allows again, or at the end).
"""

from __future__ import annotations

import json
import os
import time
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

PER_S = 10.0  # lines a second at most (and as many at once)


class SecurityLog:
    """Refused attempts, appended to ``path`` (owner-only, made so if new) as they happen, rate-limited."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        self._file = os.fdopen(fd, "a", buffering=1)  # (a line each: written as it happens)
        self._budget, self._at = PER_S, None
        self.suppressed: Counter = Counter()  # by reason, since the last line
        self.written = 0

    def refused(self, source: tuple | str, reason: str, now: float | None = None, **more) -> None:
        """One refused attempt from ``source`` (an address, or e.g. "keypad"), ``reason`` as counted."""
        now = time.monotonic() if now is None else now
        self._budget = min(PER_S, self._budget + max(0.0, now - (now if self._at is None else self._at)) * PER_S)
        self._at = now
        if self._budget < 1.0:
            self.suppressed[reason] += 1
            return
        self._budget -= 1.0
        if self.suppressed:
            self._budget -= 1.0
            self._flush_suppressed()
        where = f"{source[0]}:{source[1]}" if isinstance(source, tuple) else source
        self._write({"at": _now(), "source": where, "reason": reason, **more})

    def note(self, event: str, **fields) -> None:
        """An event that is no refusal (a key reloaded, a session ended by it), never rate-limited."""
        self._write({"at": _now(), "event": event, **fields})

    def close(self) -> None:
        if self.suppressed:
            self._flush_suppressed()
        self._file.close()

    def _flush_suppressed(self) -> None:
        self._write({"at": _now(), "suppressed": sum(self.suppressed.values()), "by_reason": dict(self.suppressed)})
        self.suppressed.clear()

    def _write(self, record: dict) -> None:
        self._file.write(json.dumps(record) + "\n")
        self.written += 1


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")
