"""``derivatives/rehabkit/``: each session's outcome measures, a row per run, as the rehab layer computed them at the
end of the run (``summary.json``'s metrics: :mod:`rehabkit.rehab.run_outcomes`), with a sidecar giving each
measure's description and unit and the participant's ranges of motion from their profile (what ``rehabkit
progress`` draws the ranges reached against)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from rehabkit.bids.run_folder import RunFolder
from rehabkit.bids.sidecars import BIDS_VERSION
from rehabkit.bids.tables import read_tsv, write_json, write_tsv
from rehabkit.core.version import __version__

FOLDER = Path("derivatives") / "rehabkit"
FIRST = ("reaches", "reaches_completed", "sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio",
         "peak_interaction_force_n", "safety_interventions")
UNITS = {"count": None, "1": None}


def outcomes_path(root: Path, sub: str, ses: str) -> Path:
    return root / FOLDER / sub / ses / f"{sub}_{ses}_outcomes.tsv"


def _committed(root: Path, sub: str, ses: str) -> set[tuple[str, str]]:
    scans = root / sub / ses / f"{sub}_{ses}_scans.tsv"
    return {(m[1], m[2]) for r in read_tsv(scans) if (m := re.search(r"_task-([A-Za-z0-9]+)_.*run-(\d+)_",
                                                                     r["filename"]))}


def add_run(root: Path, sub: str, ses: str, task: str, n: int, run: RunFolder) -> None:
    """``run``'s outcome measures as a row of its session's table (rows of runs not in the dataset dropped)."""
    path = outcomes_path(root, sub, ses)
    keep = _committed(root, sub, ses)
    rows = [r for r in read_tsv(path) if (r["task"], r["run"]) in keep and (r["task"], r["run"]) != (task, str(n))]
    metrics, info = run.summary.get("metrics", {}), run.summary.get("metric_info", {})
    measures = [k for k in metrics if info.get(k, {}).get("outcome")]
    ordered = [k for k in FIRST if k in measures] + [k for k in measures if k not in FIRST]
    rows.append({"task": task, "run": str(n), "acq_time": run.started.strftime("%Y-%m-%dT%H:%M:%S"),
                 **{k: metrics[k] for k in ordered}})
    columns = list(dict.fromkeys(["task", "run", "acq_time", *(k for r in rows for k in r)]))
    sidecar = path.with_suffix(".json")
    described: dict[str, Any] = json.loads(sidecar.read_text()) if sidecar.exists() else {}
    described |= {"task": {"Description": "the run's task (its scenario's name)"},
                  "run": {"Description": "the run's index in the session, as in its motion files' run-<index>"},
                  "acq_time": {"Description": "when the run began (UTC)"}}
    for k in ordered:
        unit = info.get(k, {}).get("unit")
        described[k] = {"Description": info.get(k, {}).get("description", k),
                        **({"Units": unit} if unit and UNITS.get(unit, unit) else {})}
    profile = run.profile or {}
    described["ProfileRanges"] = {
        "Description": "the participant's ranges of motion per joint from their profile (degrees): passive, what "
                       "the joint can be moved through; active, what they move on their own",
        "ProfileVersion": profile.get("version", 1),
        "Joints": {j: {k: r[k] for k in ("passive_deg", "active_deg") if r.get(k) is not None}
                   for j, r in (profile.get("joints") or {}).items()}}
    write_json(sidecar, described)
    write_tsv(path, columns, sorted(rows, key=lambda r: (r["task"], int(r["run"]))))


def describe(root: Path, raw: dict[str, Any]) -> None:
    """The derivative dataset's own description (its authors and licence the raw dataset's), README and
    ``.bidsignore`` (BIDS has no name for a session's outcome table: the validator is told to leave it)."""
    from rehabkit.bids.tables import write_file

    write_json(root / FOLDER / "dataset_description.json", {
        "Name": f"rehabkit outcome measures of {raw['Name']}", "BIDSVersion": BIDS_VERSION,
        "DatasetType": "derivative", "Authors": raw.get("Authors", ["n/a"]), "License": raw.get("License", "n/a"),
        "GeneratedBy": [{"Name": "rehabkit", "Version": __version__,
                         "Description": "the outcome measures each run's summary.json holds (rehabkit.rehab)"}],
        "DatasetLinks": {"raw": "../../"}, "SourceDatasets": [{"URL": "bids:raw:"}]})
    write_file(root / FOLDER / ".bidsignore", "*_outcomes.tsv\n*_outcomes.json\nprogress.html\n")
    write_file(root / FOLDER / "README.md", f"""# Outcome measures of {raw['Name']}

`sub-<label>/ses-<label>/sub-<label>_ses-<label>_outcomes.tsv`: a row per run of the session (its task and run index,
as in the raw dataset's file names), each column an outcome measure the rehab layer of rehabkit computed at the end of
the run: the number of reaches and those completed, SPARC (smoothness of the hand's speed), the path-length ratio, the
time to target, the assistance ratio (the robot's share of the positive work), the peak interaction force, the safety
layer's interventions and each joint's range of motion. The JSON sidecar beside it gives each measure's description
and units, and the participant's ranges of motion from their profile. `rehabkit progress` draws them across sessions.
""")


def read_outcomes(root: Path) -> dict[str, list[dict[str, Any]]]:
    """Every participant's outcome rows, each with its ``session`` and the session's sidecar (``ranges``), in
    session order: participant → rows."""
    out: dict[str, list[dict[str, Any]]] = {}
    for path in sorted((root / FOLDER).glob("sub-*/ses-*/*_outcomes.tsv")):
        sub, ses = path.parent.parent.name, path.parent.name
        sidecar = json.loads(path.with_suffix(".json").read_text()) if path.with_suffix(".json").exists() else {}
        for row in read_tsv(path):
            out.setdefault(sub, []).append({**row, "session": ses, "sidecar": sidecar})
    for rows in out.values():
        rows.sort(key=lambda r: (r["acq_time"], r["session"], int(r["run"])))
    return out


def tidy(root: Path) -> None:
    """Rows of runs no ``scans.tsv`` lists (an export killed before its commit) dropped."""
    for path in (root / FOLDER).glob("sub-*/ses-*/*_outcomes.tsv"):
        sub, ses = path.parent.parent.name, path.parent.name
        keep = _committed(root, sub, ses)
        rows = read_tsv(path)
        kept = [r for r in rows if (r["task"], r["run"]) in keep]
        if len(kept) != len(rows):
            write_tsv(path, list(rows[0]), kept)
