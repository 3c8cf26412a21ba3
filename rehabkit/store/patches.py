"""Record-and-replay patches, kept across runs (after Stuyt et al., ARM).

Twelve patches, each either a *target* (joint values and the gripper pose they
give) or a timed *sequence* of actions ("lift up for 2 s", "close gripper").
They live in an SQLite file under the user's data directory
(``$REHABKIT_DATA`` or ``$XDG_DATA_HOME/rehabkit``, default
``~/.local/share/rehabkit``): every save is one transaction, so a crash
mid-write leaves the patches saved before it intact. The file carries an
application id and a schema version; a file that is not such a store (another
program's database, corrupt bytes) is refused with a clear error and never
overwritten.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

SLOTS = range(1, 13)
APPLICATION_ID = 0x52484B54  # "RHKT" in SQLite's application_id header field
SCHEMA_VERSION = 1


class StoreError(RuntimeError):
    """The patch store can't be used: ``path``, the file (the message says why)."""

    def __init__(self, message: str, path: Path):
        super().__init__(message)
        self.path = path


class Action(BaseModel):
    """One step of a recorded sequence, as the HMI would issue it."""

    model_config = ConfigDict(extra="forbid")

    command: str = Field(description="e.g. 'lift-up', 'joint-5+', 'gripper-close'")
    duration_s: float = Field(0.0, ge=0)


class Patch(BaseModel):
    """A stored target or action sequence."""

    model_config = ConfigDict(extra="forbid")

    kind: Literal["target", "sequence"]
    robot: str
    joints_rad: list[float] | None = None
    pose: list[list[float]] | None = Field(None, description="4x4 gripper pose in the robot base frame")
    actions: list[Action] | None = None
    net_motion_rad: list[float] | None = Field(None, description="sequence: the joint change it made when recorded")
    recorded_at: float = Field(default_factory=time.time)

    @model_validator(mode="after")
    def _consistent(self) -> Patch:
        if self.kind == "target" and self.joints_rad is None:
            raise ValueError("a target patch needs joints_rad")
        if self.kind == "sequence" and not self.actions:
            raise ValueError("a sequence patch needs at least one action")
        return self


def default_path() -> Path:
    root = os.environ.get("REHABKIT_DATA") or Path(os.environ.get("XDG_DATA_HOME", Path.home() / ".local" / "share"))
    return Path(root) / ("" if os.environ.get("REHABKIT_DATA") else "rehabkit") / "patches.sqlite"


class PatchStore:
    """The twelve patches of one user, in one SQLite file."""

    def __init__(self, path: str | Path | None = None):
        self.path = Path(path) if path is not None else default_path()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        existed = self.path.exists() and self.path.stat().st_size > 0
        try:
            if existed:  # identify the file read-only first: even setting the journal mode writes to it
                probe = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
                try:
                    self._check(probe)
                finally:
                    probe.close()
            self.db = sqlite3.connect(self.path, isolation_level=None)  # explicit transactions below
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=FULL")
            if not existed:
                self._create()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.path} is not a rehabkit patch store ({exc}); it was left untouched — "
                             "move it away or set REHABKIT_DATA to another folder", self.path) from None

    def run_state(self) -> list[tuple[int, str]]:
        """The patches as they are now (a run session's snapshot takes them with the keypad's state)."""
        return self.db.execute("SELECT slot, body FROM patches ORDER BY slot").fetchall()

    def restore_run_state(self, rows: list[tuple[int, str]]) -> None:
        """The patches as :meth:`run_state` took them, in one transaction."""
        with self._transaction():
            self.db.execute("DELETE FROM patches")
            self.db.executemany("INSERT INTO patches (slot, body) VALUES (?, ?)", rows)

    @classmethod
    def in_memory(cls) -> PatchStore:
        """A fresh store that writes no file: a run's own, when the run has no folder to keep it in."""
        store = cls.__new__(cls)
        store.path = Path(":memory:")
        store.db = sqlite3.connect(":memory:", isolation_level=None)
        store._create()
        return store

    @classmethod
    def probe(cls, path: Path) -> None:
        """Check an existing store file read-only (a missing one is fine: a run would make it)."""
        if not (path.exists() and path.stat().st_size > 0):
            return
        store = cls.__new__(cls)
        store.path = path
        try:
            db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
            try:
                store._check(db)
            finally:
                db.close()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{path} is not a rehabkit patch store ({exc}); it was left untouched — "
                             "move it away or set REHABKIT_DATA to another folder", Path(path)) from None

    def _create(self) -> None:
        with self._transaction():
            self.db.execute(f"PRAGMA application_id={APPLICATION_ID}")
            self.db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            self.db.execute("CREATE TABLE patches (slot INTEGER PRIMARY KEY CHECK (slot BETWEEN 1 AND 12), "
                            "body TEXT NOT NULL)")

    def _check(self, db: sqlite3.Connection) -> None:
        app = db.execute("PRAGMA application_id").fetchone()[0]
        if app != APPLICATION_ID:
            raise StoreError(f"{self.path} belongs to another program (SQLite application id {app:#x}); "
                             "it was left untouched — move it away or set REHABKIT_DATA to another folder", self.path)
        version = db.execute("PRAGMA user_version").fetchone()[0]
        if version != SCHEMA_VERSION:
            raise StoreError(f"{self.path} has patch-store schema {version}; this rehabkit reads {SCHEMA_VERSION}",
                             self.path)
        problems = db.execute("PRAGMA integrity_check").fetchall()
        if problems != [("ok",)]:
            raise StoreError(f"{self.path} is damaged ({problems[0][0]}); it was left untouched", self.path)

    def _transaction(self):
        db = self.db

        class _Tx:
            def __enter__(self):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self, kind, exc, tb):
                db.execute("COMMIT" if kind is None else "ROLLBACK")

        return _Tx()

    @staticmethod
    def _slot(slot: int) -> int:
        if slot not in SLOTS:
            raise ValueError(f"patch slots are 1..12, not {slot}")
        return slot

    def save(self, slot: int, patch: Patch) -> None:
        """Store ``patch`` in ``slot`` (replacing what was there), atomically."""
        body = patch.model_dump_json()
        with self._transaction():
            self.db.execute("INSERT OR REPLACE INTO patches (slot, body) VALUES (?, ?)", (self._slot(slot), body))

    def load(self, slot: int) -> Patch | None:
        row = self.db.execute("SELECT body FROM patches WHERE slot = ?", (self._slot(slot),)).fetchone()
        return None if row is None else Patch.model_validate(json.loads(row[0]))

    def all(self) -> dict[int, Patch]:
        return {slot: Patch.model_validate(json.loads(body))
                for slot, body in self.db.execute("SELECT slot, body FROM patches ORDER BY slot")}

    def clear(self, slot: int) -> None:
        with self._transaction():
            self.db.execute("DELETE FROM patches WHERE slot = ?", (self._slot(slot),))

    def close(self) -> None:
        self.db.close()


def open_store(where: str, out_dir: Path | None, resolve: Callable[[str], Path],
               dry: bool = False) -> PatchStore | None:
    """``where``: 'user' (:func:`default_path`), 'run' (a fresh store in the run's folder ``out_dir``; in memory
    when the run writes no outputs, ``out_dir`` None) or a path (``resolve`` makes it absolute: the plugin
    context's). A store that can't be opened raises ``ValueError``. ``dry`` (a scenario checked, not run): an
    existing file is only checked, read-only; nothing is opened or made."""
    if where == "user":
        path = default_path()
    elif where == "run":
        if dry:
            return None
        if out_dir is None:  # (a run in a test or a notebook that writes nothing: nor does its store)
            return PatchStore.in_memory()
        path = out_dir / "patches.sqlite"
        path.unlink(missing_ok=True)
    else:
        path = resolve(where)
    try:
        if dry:
            PatchStore.probe(path)
            return None
        return PatchStore(path)
    except StoreError as exc:
        raise ValueError(str(exc)) from exc  # (the store's error, its file, kept as the cause)
