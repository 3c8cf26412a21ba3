"""The e-stop latch (ISO 13850): once pressed, an e-stop stays latched — across sessions, restarts of the program
holding it, and power cycles of the machine keeping the file — until a person deliberately clears it; only then
does the next session start, and it ramps in.

A latch is a small JSON file, written whole (temp, then rename), under ``$REHABKIT_STATE/estop/`` (default
``$XDG_STATE_HOME/rehabkit/estop/``, ``~/.local/state/rehabkit/estop/``: each user's own, in a folder only its owner
may read or write, on a PC a lab shares), named for what it latches: ``<robot>-<robot id>`` for a robot behind a
bridge or on its own CAN drives (the bridge, the drives' master keep it), ``sim-<robot>`` for a simulated robot (the
MuJoCo backend, and the master of simulated drives, keep it: a rehearsal behaves as the robot will and never latches
the robot). ``rehabkit estop list`` shows them, ``rehabkit estop clear NAME --by WHO`` clears one.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

from rehabkit.core.io import atomic_write_text

RAMP_IN_AFTER_CLEAR_S = 1.0  # the first session after a clear ramps in at least this long


def state_dir() -> Path:
    """Where rehabkit keeps state across sessions on this machine."""
    given = os.environ.get("REHABKIT_STATE")
    if given:
        return Path(given)
    xdg = os.environ.get("XDG_STATE_HOME")
    return (Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".local" / "state") / "rehabkit"


@contextlib.contextmanager
def own_state(folder: Path) -> Iterator[None]:
    """Keep rehabkit's state across sessions (e-stop latches) in ``folder`` meanwhile (a test, a report's runs)."""
    before = os.environ.get("REHABKIT_STATE")
    os.environ["REHABKIT_STATE"] = str(folder)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("REHABKIT_STATE", None)
        else:
            os.environ["REHABKIT_STATE"] = before


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


class EStopLatch:
    """One e-stop latch, kept in a file."""

    def __init__(self, path: Path, name: str):
        self.path, self.name = Path(path), name

    @classmethod
    def named(cls, name: str, path: str | Path | None = None) -> EStopLatch:
        return cls(Path(path) if path else state_dir() / "estop" / f"{name}.json", name)

    @classmethod
    def for_robot(cls, robot: str, robot_id: int, path: str | Path | None = None) -> EStopLatch:
        """The latch a bridge keeps for its robot."""
        return cls.named(f"{robot}-{robot_id}", path)

    def record(self) -> dict:
        """The latch's record (``{}`` if it was never pressed)."""
        try:
            return json.loads(self.path.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            return {}

    def latched(self) -> dict | None:
        """The record of the press holding it latched, or None."""
        rec = self.record()
        return rec if rec.get("latched") else None

    def press(self, reason: str, by: str, source: str | None = None) -> None:
        """Latch (a press while latched keeps the first press's record). ``source``: which device at ``by`` pressed
        it, as a code (``button``, ``keypad``), kept as the record's ``source`` where given."""
        if self.latched() is None:
            self._write({"latched": True, "since": _now(), "reason": reason, "by": by, "ramp_in_pending": False,
                         **({"source": source} if source is not None else {})})  # (the device as a field)

    def clear(self, by: str, **how: str) -> dict | None:
        """Clear it, deliberately (``by``: who; ``how``: e.g. over which link, in which session, with which key id,
        kept with it); the next session must ramp in. The press cleared, or None. Every clear, and every try at one
        where nothing was latched, is added to the latch's history (:attr:`history`), never rewritten."""
        was = self.latched()
        if was is not None:
            self._write({"latched": False, "cleared": _now(), "cleared_by": by, **how, "was": was,
                         "ramp_in_pending": True})
        self._append({"at": _now(), "cleared_by": by, **how, "was_latched": was is not None,
                      **({"latched_since": was.get("since"), "reason": was.get("reason")} if was else {})})
        return was

    @property
    def history(self) -> Path:
        """The latch's clears, one JSON line each, appended only: ``<name>.history.jsonl`` beside it."""
        return self.path.with_name(f"{self.path.stem}.history.jsonl")

    def cleared(self) -> list[dict]:
        """The latch's history: every clear, oldest first."""
        try:
            return [json.loads(line) for line in self.history.read_text().splitlines() if line.strip()]
        except FileNotFoundError:
            return []

    def _append(self, record: dict) -> None:
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(self.history, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        try:
            os.write(fd, (json.dumps({**record, "name": self.name}) + "\n").encode())
            os.fsync(fd)
        finally:
            os.close(fd)

    def take_ramp_in(self) -> bool:
        """Whether this session is the first after a clear (it must ramp in); marks that it has been."""
        rec = self.record()
        if rec.get("ramp_in_pending") and not rec.get("latched"):
            self._write({**rec, "ramp_in_pending": False, "ramped_in": _now()})
            return True
        return False

    def describe(self) -> str:
        rec = self.latched()
        if rec is None:
            return f"{self.name}: not latched"
        return f"{self.name}: LATCHED since {rec['since']} by {rec['by']} ({rec['reason']})"

    def refusal(self, where: str) -> str:
        """Why a session does not start, and how to go on."""
        rec = self.latched() or {}
        return (f"the e-stop of {where} is latched (since {rec.get('since', '?')}, {rec.get('reason', 'pressed')}): "
                f"deal with its cause, then clear it with `rehabkit estop clear {self.name} --by NAME`")

    def _write(self, record: dict) -> None:
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)  # (the user's own: no one else's to clear)
        atomic_write_text(self.path, json.dumps({**record, "name": self.name, "written": time.time()}, indent=1))


def all_latches() -> list[EStopLatch]:
    """Every latch kept on this machine."""
    folder = state_dir() / "estop"
    return [EStopLatch(p, p.stem) for p in sorted(folder.glob("*.json"))] if folder.is_dir() else []
