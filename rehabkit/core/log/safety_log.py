"""A tamper-evident record of a run's safety: what was in force and what the safety layer did, as JSON lines whose
hashes chain them (``safety_log.jsonl`` in the run's folder; ``rehabkit audit RUN_DIR`` checks and prints it).

Each record carries the hash of the one before it and its own: SHA-256 over the previous hash and the record's
canonical JSON — or, with ``REHABKIT_AUDIT_KEY`` set, HMAC-SHA256 under that key. Without a key an edit shows unless
every later hash is recomputed too (keep the last hash, printed at the end of a run, somewhere else, e.g. the lab
notebook); with a key, recomputing them needs the key.

The records: the run (software version, the scenario as it ran and its SHA-256, the plugins with their packages'
versions, the patient's id, the backend), every limit in force with where it came from, each intervention, the end.

The log is written as the run goes (:class:`SafetyLog`, opened with the run's session when it has a folder), in place
under its final name, appended to one write per record: the run and limits records at the start, each trip as it
happens — on disk (``fsync``) before the safety layer begins the stop it calls for — and the routine interventions
(ramps, clipping episodes, the brakes) batched: with the next trip, every ``FLUSH_S`` seconds, or at the finish, which
writes what is left, the robot side's interventions and the ``end`` record. A run killed on the way leaves a log
valid up to its last complete line and without its ``end`` record; ``rehabkit audit`` checks it so (:func:`check`).
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import logging
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rehabkit.core.io import atomic_write_text

LOG = "safety_log.jsonl"
# the scenario as it ran beside the log (the text its run record hashes), written as the session opens: what `rehabkit
# replay` starts from, kept by a killed run too
SNAPSHOT = "scenario.yaml"
KEY_ENV = "REHABKIT_AUDIT_KEY"
GENESIS = "0" * 64
FLUSH_S = 1.0  # routine records wait at most this long (wall clock) to be written, unless a clipping episode lasts
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's emitter where installed


def _canonical(body: dict[str, Any]) -> bytes:
    return json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=float).encode()


def _digest(prev: str, body: dict[str, Any], key: bytes | None) -> str:
    data = prev.encode() + _canonical(body)
    return hmac.new(key, data, hashlib.sha256).hexdigest() if key else hashlib.sha256(data).hexdigest()


def audit_key() -> bytes | None:
    """The key in ``REHABKIT_AUDIT_KEY``, if one is set."""
    key = os.environ.get(KEY_ENV)
    return key.encode() if key else None


def chain(records: list[dict[str, Any]], key: bytes | None = None) -> str:
    """The records as hash-chained JSON lines (``seq``, ``prev`` and ``hash`` added to each)."""
    lines, prev = [], GENESIS
    for seq, record in enumerate(records):
        body = {"seq": seq, "prev": prev, **record}
        prev = _digest(prev, body, key)
        lines.append(json.dumps({**body, "hash": prev}, ensure_ascii=False, default=float))
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class ChainBreak:
    """Where a log's chain does not hold: at ``line`` (1-based), record ``seq`` of ``kind`` (None: not a record),
    and the ``fault``: ``"unreadable"`` (not a record of this log), ``"out-of-order"`` (it does not follow the record
    before it), ``"edited"`` (its content does not match its hash; ``keyed``: checked with the audit key) or
    ``"empty"`` (no records at all)."""

    line: int
    seq: Any
    kind: Any
    fault: str
    keyed: bool = False

    def __str__(self) -> str:
        if self.fault == "empty":
            return "the log holds no records"
        if self.fault == "unreadable":
            return f"line {self.line}: not a record of this log"
        what = f"record {self.seq} ({self.kind}, line {self.line})"
        if self.fault == "out-of-order":
            return f"{what}: does not follow the record before it (one removed, inserted or reordered)"
        return (f"{what}: its content does not match its hash (edited"
                f"{'' if self.keyed else ', or checked without the key it was written with'})")


@dataclass(frozen=True)
class LogCheck:
    """A log checked: its records, what is wrong with its chain (nothing: intact), a torn last line left out (a
    write cut short: the process killed or the machine down while it wrote), and whether it has its ``end``."""

    records: list[dict[str, Any]]
    problems: list[ChainBreak]
    torn: str | None = None  # the last line's start, when it was left out unfinished

    @property
    def finished(self) -> bool:
        """The log ends with its closing record: the run was finished (else it was killed on the way)."""
        return bool(self.records) and self.records[-1].get("kind") == "end"


def verify(path: Path, key: bytes | None = None) -> tuple[list[dict[str, Any]], list[ChainBreak]]:
    """The records of a log and what is wrong with its chain (nothing: intact); a torn last line is left out."""
    checked = check(path, key)
    return checked.records, checked.problems


def check(path: Path, key: bytes | None = None) -> LogCheck:
    """A log's chain checked up to its last complete record (see :class:`LogCheck`). A last line without its newline
    that is not a whole record is a write cut short, left out and said (one earlier, or with its newline, is not)."""
    # (lines end at "\n" alone: a message may hold a character splitlines() would also break at)
    *lines, last = Path(path).read_text(errors="replace").split("\n")
    torn = None
    if last:  # no newline after it: whole, or cut short
        try:
            json.loads(last)["hash"]
            lines.append(last)
        except (ValueError, KeyError, TypeError):
            torn = last[:60]
    records, problems, prev = [], [], GENESIS
    for number, line in enumerate(lines, start=1):
        try:
            record = json.loads(line)
            body = {k: v for k, v in record.items() if k != "hash"}
            stated = record["hash"]
        except (ValueError, KeyError, AttributeError):
            problems.append(ChainBreak(number, None, None, "unreadable"))
            continue
        seq, kind = record.get("seq", "?"), record.get("kind", "?")
        if record.get("prev") != prev:
            problems.append(ChainBreak(number, seq, kind, "out-of-order"))
        if _digest(record.get("prev", ""), body, key) != stated:
            problems.append(ChainBreak(number, seq, kind, "edited", key is not None))
        records.append(record)
        prev = stated
    if not records:
        problems.append(ChainBreak(0, None, None, "empty"))
    return LogCheck(records, problems, torn)


def joint_limits(lim: Any, j: int, revolute: bool, narrowed_by: dict) -> dict[str, Any]:
    """Joint ``j``'s limits in its own units: degrees and N·m for a revolute joint, metres and N for a prismatic."""
    if revolute:
        return {"lower_deg": round(float(np.degrees(lim.lower[j])), 6), "upper_deg": round(float(np.degrees(
            lim.upper[j])), 6), "velocity_deg_s": round(float(np.degrees(lim.velocity[j])), 6),
            "effort_nm": round(float(lim.effort[j]), 6), "narrowed_by": narrowed_by}
    return {"lower_m": round(float(lim.lower[j]), 6), "upper_m": round(float(lim.upper[j]), 6),
            "velocity_m_s": round(float(lim.velocity[j]), 6), "effort_n": round(float(lim.effort[j]), 6),
            "narrowed_by": narrowed_by}


def kind_settings(safety: Any, revolute: np.ndarray) -> dict[str, Any]:
    """The envelope's settings for every joint of a kind, for the kinds the robot has: how far beyond its range a
    joint trips and a controlled stop's deceleration bound (None: each drive's own) — a revolute joint's in degrees,
    a prismatic joint's in metres."""
    out: dict[str, Any] = {}
    if np.any(revolute):
        out.update(position_margin_deg=safety.position_margin_deg, stop_decel_deg_s2=safety.stop_decel_deg_s2)
    if not np.all(revolute):
        out.update(position_margin_m=safety.position_margin_m, stop_decel_m_s2=safety.stop_decel_m_s2)
    return out


def scenario_text(a: Any) -> str:
    """The scenario as the run used it, as ``scenario.yaml`` in the run's folder holds it (the run record's SHA-256
    is this text's)."""
    return (f"# {a.loaded.path} as this run used it (extends merged, profile inlined, --set applied); "
            "`rehabkit replay` reads it\n" + yaml.dump(a.loaded.source.data, Dumper=_DUMPER, sort_keys=False))


def opening_records(a: Any, scenario: str, patient: Any = None) -> list[dict[str, Any]]:
    """What a run's log starts with, known before it moves (``a``: its
    :class:`~rehabkit.core.setup.assembly.Assembly`, the backend reset): the run and the limits in force.
    ``patient``: who the run is for (default: the id in the scenario's ``patient`` section, if any)."""
    from rehabkit.core.results.summary import plugin_versions  # (the results import the run's parts)
    from rehabkit.core.version import __version__

    sc = a.sc
    if patient is None:
        patient = getattr(getattr(sc, "patient", None), "id", None)
    used = plugin_versions(a)  # kind → type, package, version; sensors by name
    plugins = {f"{kind}:{p['type']}": f"{p['package']} {p['version']}" for kind, p in used.items() if kind != "sensors"}
    plugins.update({f"sensor:{p['type']}": f"{p['package']} {p['version']}" for p in used["sensors"].values()})
    model, lim = a.robot.model, a.limits
    sources = a.limit_sources.as_dict()
    joints = {name: joint_limits(lim, j, turns, sources.get(name, {}))
              for j, (name, turns) in enumerate(zip(model.joint_names, model.revolute, strict=True))}
    safety = a.safety.config
    return [
        {"kind": "run", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "software": {"rehabkit": __version__},
         "scenario": {"file": str(a.loaded.path), "sha256": hashlib.sha256(scenario.encode()).hexdigest()},
         "plugins": plugins, "patient": patient, "backend": sc.backend.type,
         **({"link": link} if (link := a.backend.provenance()) else {}),
         "seed": sc.seed, "keyed": audit_key() is not None},
        {"kind": "limits", "joints": joints, **kind_settings(safety, model.revolute),
         "interaction_force_n": safety.interaction_force_n,
         "keep_in": safety.keep_in.model_dump(mode="json") if safety.keep_in is not None else None,
         "stop": model.safe_stop, "stop_category": a.safety.categories,
         "brakes_nm": model.brakes.tolist() if model.brakes is not None else None,
         "stop_after_s": safety.stop_after_s},
    ]


def end_record(summary: dict[str, Any]) -> dict[str, Any]:
    """The closing record: the run's verdict, its safety events, how far it ran."""
    return {"kind": "end", "passed": summary.get("passed"), "safety_events": summary["metrics"].get("safety_events"),
            "sim_time_s": summary["metrics"].get("sim_time_s")}


def run_records(a: Any, scenario_text: str, summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The records of a finished run, all at once (``a``: its :class:`~rehabkit.core.setup.assembly.Assembly`)."""
    patient = (summary.get("patient") or {}).get("id")  # (the rehab layer's section says who the run was for)
    return [*opening_records(a, scenario_text, patient),
            *({"kind": "intervention", **event} for event in summary["safety"]["interventions"]),
            end_record(summary)]


class SafetyLog:
    """A run's safety log written as the run goes (the module docstring): ``path`` created (emptied) and the
    ``opening`` records on disk at once; then :meth:`tripped` — the safety layer's ``on_event`` — writes each trip
    (after the routine records before it) and syncs it to disk before the layer acts on it; a background thread writes
    the routine records of ``layer.interventions`` every ``FLUSH_S`` seconds (but a clipping episode that may still
    grow, and what came after it); :meth:`close` writes the rest and the ``end``, :meth:`discard` removes the log (a
    run that never ran), :meth:`abandon` leaves it as it stands (a run whose end failed).

    A write the disk refused does not hold up a stop: the records are kept, and :meth:`close` writes them whole
    instead (temporary file, then rename)."""

    def __init__(self, path: Path, layer: Any, opening: list[dict[str, Any]], key: bytes | None = None,
                 flush_s: float = FLUSH_S):
        self.path, self._layer, self._key = Path(path), layer, key
        self._prev, self._lines, self._written = GENESIS, [], 0  # (_written: how many of the layer's interventions)
        self._lock = threading.Lock()
        self._failed: OSError | None = None
        self.scenario: str | None = None  # the scenario's text the run record hashes (scenario.yaml's)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND | os.O_CLOEXEC,
                                       0o666)
        try:
            for record in opening:
                self._append(record)
            self._sync()
            _sync_dir(self.path.parent)  # (the file's name on disk too)
        except BaseException:
            self.discard()
            raise
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._flusher, args=(flush_s,), name="rehabkit-safety-log",
                                        daemon=True)
        self._thread.start()

    @property
    def last_hash(self) -> str:
        return self._prev

    def tripped(self, event: Any = None) -> None:
        """A trip (``event``, the last of the layer's interventions): it and every routine record before it written,
        and on disk before this returns."""
        with self._lock:
            if self._fd is None:
                return
            self._pending(everything=True)
            self._sync()

    def close(self, later: list[Any], summary: dict[str, Any]) -> str:
        """The finish: the routine records left, ``later`` (the robot side's interventions, known at the end) and the
        ``end`` record written and on disk, the file closed; returns the last hash."""
        self._stop_flusher()
        with self._lock:
            if self._fd is None:
                raise ValueError(f"{self.path}: the safety log was closed already")
            self._pending(everything=True)
            for event in later:
                self._append({"kind": "intervention", **event.as_dict()})
            self._append(end_record(summary))
            self._sync()
            os.close(self._fd)
            self._fd = None
            if self._failed is not None:  # (what the disk refused on the way: the log written whole now)
                atomic_write_text(self.path, "".join(self._lines))
        return self._prev

    def abandon(self) -> None:
        """Close the log as it stands, the routine records written but no ``end``: the run ran, and its finish
        failed (``rehabkit audit`` says the log ends without its closing record)."""
        self._stop_flusher()
        with self._lock:
            if self._fd is not None:
                self._pending(everything=True)
                self._sync()
                os.close(self._fd)
                self._fd = None

    def discard(self) -> None:
        """No log: the run never ran (its setup failed)."""
        if getattr(self, "_thread", None) is not None:
            self._stop_flusher()
        with self._lock:
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None
            self.path.unlink(missing_ok=True)

    # -- the writing ---------------------------------------------------------------------------------------

    def _append(self, record: dict[str, Any]) -> None:
        """One record chained onto the last, in one write (held, not written, once the disk refused one)."""
        body = {"seq": len(self._lines), "prev": self._prev, **record}
        self._prev = _digest(self._prev, body, self._key)
        line = json.dumps({**body, "hash": self._prev}, ensure_ascii=False, default=float) + "\n"
        self._lines.append(line)
        if self._failed is None:
            try:
                data = line.encode()
                while data:  # (a regular file takes it in one write; a short one is finished)
                    data = data[os.write(self._fd, data):]
            except OSError as exc:
                self._failed = exc
                logging.getLogger(__name__).error("%s: can't append to the safety log (%s); it is written whole at "
                                                  "the run's end", self.path, exc)

    def _sync(self) -> None:
        if self._failed is None:
            try:
                os.fsync(self._fd)
            except OSError as exc:
                self._failed = exc

    def _pending(self, everything: bool) -> bool:
        """The layer's interventions not written yet, written (with the lock held); ``everything``: a clipping
        episode still under way too (else it and what came after it wait). Whether any was."""
        events = self._layer.interventions
        start = min(self._written, len(events))  # (a session put back to an earlier state holds fewer)
        pending = events[start:]
        if not everything and (growing := self._layer.growing) is not None:
            pending = pending[:next((i for i, e in enumerate(pending) if e is growing), len(pending))]
        for event in pending:
            self._append({"kind": "intervention", **event.as_dict()})
        self._written = start + len(pending)
        return bool(pending)

    def flush_routine(self) -> None:
        """The routine records so far written and on disk (a clipping episode still under way, and what came after
        it, wait): what the flusher thread does every ``flush_s`` seconds while the run goes. Synced outside the lock:
        a trip meanwhile waits for no disk but its own."""
        with self._lock:
            wrote = self._fd is not None and self._pending(everything=False)
            fd = self._fd
        if wrote and self._failed is None:
            with contextlib.suppress(OSError):  # (the next trip's or the finish's sync says it)
                os.fsync(fd)

    def _flusher(self, every: float) -> None:
        while not self._halt.wait(every):
            self.flush_routine()

    def _stop_flusher(self) -> None:
        self._halt.set()
        if self._thread is not threading.current_thread():
            self._thread.join()


def _sync_dir(folder: Path) -> None:
    """A new file's directory entry on disk (where the platform can open a directory)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def open_log(a: Any, layer: Any, scenario: str | None = None, folder: Path | None = None) -> SafetyLog:
    """The run's safety log opened in its folder (``folder``, by default ``a.out_dir``), written from now on: its
    opening records on disk, ``layer`` (the session's :class:`~rehabkit.core.safety.layer.SafetyLayer`) telling it each
    trip before acting on it. ``scenario``: the scenario's text as the run used it (:func:`scenario_text`, made here
    if not given)."""
    text = scenario if scenario is not None else scenario_text(a)
    log = SafetyLog(Path(folder or a.out_dir) / LOG, layer, opening_records(a, text), audit_key())
    log.scenario = text
    layer.on_event = log.tripped
    return log


def write(path: Path, records: list[dict[str, Any]]) -> str:
    """Write the chained log whole (temp file, then rename); returns the last record's hash."""
    text = chain(records, audit_key())
    atomic_write_text(path, text)
    return json.loads(text.splitlines()[-1])["hash"]
