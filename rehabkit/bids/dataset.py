"""A Motion-BIDS dataset that runs are added to, safely and resumably.

Each run's files are written whole (temporary file, then rename) and the run is in the dataset once its session's
``scans.tsv`` lists it — the last file written, the commit. An export killed before then leaves files no
``scans.tsv`` lists: the next export into the dataset removes them, and adds the run again. A run already listed
(its ``rehabkit_run`` id) is not added twice, so the same command run again adds only what is missing. One export
at a time (a lock in ``.rehabkit/``).
"""

from __future__ import annotations

import fcntl
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rehabkit.bids import derivatives
from rehabkit.bids.channels import Tracksys, instrument_tracksys, robot_tracksys
from rehabkit.bids.events import COLUMNS, SIDECAR, event_rows
from rehabkit.bids.run_folder import ExportError, RunFolder, label
from rehabkit.bids.sidecars import channels_json, dataset_description, motion_json, readme
from rehabkit.bids.tables import read_tsv, tsv_text, write_file, write_json, write_motion, write_tsv
from rehabkit.core.version import __version__

CHANNEL_COLUMNS = ["name", "component", "type", "tracked_point", "units", "reference_frame", "description",
                   "sampling_frequency"]
SCANS = {"rehabkit_run": "the run's id (its safety log's hash): a run exported again is recognised by it",
         "backend": "where the session ran: mujoco (simulated), hardware (over the robot link), canopen",
         "seed": "the run's seed (a simulated person's noise, the scenario's random draws)"}


@dataclass
class Placement:
    """Where a run goes: its participant and session labels, and columns its session adds to ``sessions.tsv``
    (a sweep's grid values), each with its description."""

    participant: str
    session: str
    columns: dict[str, Any] = field(default_factory=dict)
    described: dict[str, str] = field(default_factory=dict)


def no_participant(folder: Path) -> ExportError:
    return ExportError(folder / "scenario.yaml", "patient: the run has no patient profile, and BIDS files every "
                       "recording under a participant", "give one with --participant LABEL (e.g. --participant rig "
                       "for a robot alone), or run with a profile (--set patient=FILE)")


def placement(run: RunFolder, participant: str | None = None) -> Placement:
    """The profile's id (or ``participant`` for a run without one) and the profile's session (or the run's
    date)."""
    if run.profile is None and participant is None:
        raise no_participant(run.path)
    who = label(run.profile.get("id", "") if run.profile is not None else participant)
    if not who:
        raise ExportError("--participant", f"'{participant}' has no letters or digits", "give a label like P01")
    session = (run.profile or {}).get("session") or run.started.strftime("%Y%m%d")
    return Placement(who, label(session))


@dataclass
class Added:
    """A run added: where, its files, tracking systems, events and the largest difference read back."""

    run: RunFolder
    prefix: str
    files: list[Path]
    systems: list[Tracksys]
    events: list[dict]
    largest_difference: dict[str, float]


class Dataset:
    """``root``, a dataset runs are added to (a context: locked, and left consistent, while in it)."""

    def __init__(self, root: Path | str, study: dict | None = None):
        self.root = Path(root)
        self.study = study
        self._lock = None

    def __enter__(self) -> Dataset:
        private = self.root / ".rehabkit"
        private.mkdir(parents=True, exist_ok=True)
        self._lock = open(private / "lock", "w")
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as exc:
            self._lock.close()
            raise ExportError(self.root, "another export is adding runs to this dataset", "wait for it") from exc
        import json

        kept = private / "study.json"
        saved = json.loads(kept.read_text()) if kept.exists() else {}
        self.study = {**saved, **(self.study or {})}
        if self.study != saved:
            write_json(kept, self.study)
        self._tidy()
        return self

    def __exit__(self, *exc) -> None:
        if self._lock is not None:
            self._lock.close()

    def _tidy(self) -> None:
        """What an export killed on the way left: temporary files, and files of runs no ``scans.tsv`` lists."""
        for tmp in self.root.rglob(".*.tmp"):
            tmp.unlink(missing_ok=True)
        for motion in self.root.glob("sub-*/ses-*/motion"):
            listed = {Path(r["filename"]).name for r in read_tsv(self._scans(motion.parent))}
            runs = {_run_key(n) for n in listed}
            for f in motion.iterdir():  # (a run's files: sub-…_task-…_run-<n>_…; anything else is left alone)
                if f.is_file() and f.name.startswith("sub-") and (key := _run_key(f.name)) and key not in runs:
                    f.unlink()
        derivatives.tidy(self.root)

    @staticmethod
    def _scans(session_dir: Path) -> Path:
        sub, ses = session_dir.parent.name, session_dir.name
        return session_dir / f"{sub}_{ses}_scans.tsv"

    def has(self, run_id: str) -> str | None:
        """The motion file of the run ``run_id`` where the dataset lists it already."""
        for scans in self.root.glob("sub-*/ses-*/*_scans.tsv"):
            for row in read_tsv(scans):
                if row.get("rehabkit_run") == run_id:
                    return str(scans.parent.relative_to(self.root) / row["filename"])
        return None

    def add(self, run: RunFolder, where: Placement) -> Added:
        """Write ``run``'s files, then list it in its session's ``scans.tsv``; the participant's and session's
        tables, the derivatives and the dataset's description follow."""
        sub, ses, task = f"sub-{where.participant}", f"ses-{where.session}", label(run.name) or "task"
        session_dir = self.root / sub / ses
        scans = read_tsv(self._scans(session_dir))
        taken = [int(m[1]) for r in scans if (m := re.search(rf"_task-{task}_.*run-(\d+)_", r["filename"]))]
        n = max(taken, default=0) + 1
        systems = [robot_tracksys(run)]
        systems += instrument_tracksys(run, {systems[0].label})
        base = f"{sub}_{ses}_task-{task}"
        files, diffs = [], {}
        for i, ts in enumerate(systems):
            stem = session_dir / "motion" / f"{base}_tracksys-{ts.label}_run-{n}"
            diffs[ts.label] = write_motion(stem.with_name(stem.name + "_motion.tsv"), ts.data,
                                           [c.decimals for c in ts.channels])
            write_json(stem.with_name(stem.name + "_motion.json"), motion_json(run, ts, self.study, i == 0))
            rows = [{**c.__dict__, "sampling_frequency": ts.rate_hz} for c in ts.channels]
            write_tsv(stem.with_name(stem.name + "_channels.tsv"), CHANNEL_COLUMNS, rows)
            write_json(stem.with_name(stem.name + "_channels.json"), channels_json(ts))
            files += [stem.with_name(stem.name + s) for s in ("_motion.tsv", "_motion.json", "_channels.tsv",
                                                              "_channels.json")]
        events = event_rows(run, int(systems[0].stamps[0]))
        ev = session_dir / "motion" / f"{base}_run-{n}_events"
        write_file(ev.with_suffix(".tsv"), tsv_text(list(COLUMNS), events))
        write_json(ev.with_suffix(".json"), {**SIDECAR, "StimulusPresentation": {
            "SoftwareName": "rehabkit", "SoftwareVersion": __version__, "OperatingSystem": "n/a",
            "Code": "n/a"}})
        files += [ev.with_suffix(".tsv"), ev.with_suffix(".json")]
        acq = run.started.strftime("%Y-%m-%dT%H:%M:%S")
        scans += [{"filename": f"motion/{base}_tracksys-{ts.label}_run-{n}_motion.tsv", "acq_time": acq,
                   "rehabkit_run": run.run_id, "backend": run.backend, "seed": run.summary.get("seed")}
                  for ts in systems]
        derivatives.add_run(self.root, sub, ses, task, n, run)  # (before the commit: a session's rows are rewritten)
        write_json(self._scans(session_dir).with_suffix(".json"), {k: {"Description": v} for k, v in SCANS.items()}
                   | {"acq_time": {"Description": "when the run began (UTC)"}})
        write_tsv(self._scans(session_dir), ["filename", "acq_time", *SCANS], scans)  # the commit
        self._session_row(sub, ses, acq, where)
        self._participant_row(sub, run)
        return Added(run, base + f"_run-{n}", files, systems, events, diffs)

    def _session_row(self, sub: str, ses: str, acq: str, where: Placement) -> None:
        path = self.root / sub / f"{sub}_sessions.tsv"
        rows = {r["session_id"]: r for r in read_tsv(path)}
        row = rows.get(ses, {"session_id": ses, "acq_time": acq})
        row["acq_time"] = min(row.get("acq_time") or acq, acq)
        rows[ses] = {**row, **{k: str(v) for k, v in where.columns.items()}}
        columns = list(dict.fromkeys(k for r in rows.values() for k in r))
        sidecar = path.with_suffix(".json")
        import json

        described = json.loads(sidecar.read_text()) if sidecar.exists() else {}
        described |= {"acq_time": {"Description": "when the session's first run began (UTC)"}}
        described |= {k: {"Description": v} for k, v in where.described.items()}
        write_json(sidecar, described)
        write_tsv(path, columns, sorted(rows.values(), key=lambda r: r["session_id"]))

    def _participant_row(self, sub: str, run: RunFolder) -> None:
        from rehabkit.bids.participants import participant_row, write_participants

        write_participants(self.root, sub, participant_row(sub, run))

    def finish(self) -> dict[str, Any]:
        """The dataset's description, README and the derivatives' description, from what it holds now."""
        import json

        scans = [r for f in self.root.glob("sub-*/ses-*/*_scans.tsv") for r in read_tsv(f)]
        tasks = sorted({m[1] for r in scans if (m := re.search(r"_task-([A-Za-z0-9]+)_", r["filename"]))})
        simulated = bool(scans) and all(r.get("backend") == "mujoco" for r in scans)
        desc = dataset_description(self.study or {}, simulated, tasks)
        path = self.root / "dataset_description.json"
        if path.exists():  # (keys added by hand, or by a repository — a DOI — are kept; the study's are --study's)
            desc = {**json.loads(path.read_text()), **desc}
        write_json(path, desc)
        subjects = {r for r in self.root.glob("sub-*") if r.is_dir()}
        sessions = list(self.root.glob("sub-*/ses-*"))
        runs = len({r["rehabkit_run"] for r in scans})
        write_file(self.root / "README.md", readme(desc, len(subjects), len(sessions), runs, simulated))
        derivatives.describe(self.root, desc)
        return desc


def _run_key(name: str) -> tuple[str, str] | None:
    """(task, run) of a run's file name."""
    m = re.search(r"_task-([A-Za-z0-9]+)_.*run-(\d+)_", name)
    return (m[1], m[2]) if m else None
