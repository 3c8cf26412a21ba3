"""The commands of this layer, registered by ``rehabkit/cli/main.py`` (:func:`add_parser`):

- ``rehabkit export bids RUN_DIR... --out DATASET [--participant LABEL] [--study FILE]``: finished runs into one
  Motion-BIDS dataset (added to it where it exists; a run already there is not added again);
- ``rehabkit progress DATASET [--participant ID] [--out FILE]``: each participant's outcome measures across sessions,
  an HTML page with its figures in it;
- :func:`export_sweep`: a sweep's runs (``rehabkit sweep ... --bids DATASET``), its simulated people as participants.

Exit codes as every command's (``rehabkit/cli/exits.py``): 0 done, 2 bad input (said with the file or field and the
fix; nothing of a run that was refused is written).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path
from typing import Any

EXIT_OK, EXIT_INVALID = 0, 2  # (rehabkit/cli/exits.py's)


def _err(text: str) -> None:
    print(text, file=sys.stderr)


def _said(added) -> str:
    parts = []
    for ts in added.systems:
        counts = ", ".join(f"{t} {n}" for t, n in ts.counts().items())
        parts.append(f"tracksys-{ts.label} {len(ts.channels)} channels ({counts}) × {len(ts.stamps)} samples at "
                     f"{ts.rate_hz:g} Hz")
    diff = max(added.largest_difference.values(), default=0.0)
    return f"{'; '.join(parts)}; {len(added.events)} events; read back: largest difference {diff:.2g}"


def export_runs(dirs: list[str | Path], out: str | Path, study: dict | None = None, participant: str | None = None,
                placements: dict[str, Any] | None = None, say=print) -> dict[str, Any]:
    """``dirs`` (run folders) added to the dataset ``out``; ``placements``: run folder → :class:`Placement` (a
    sweep's). Returns what was done: ``added`` (each :class:`Added`), ``skipped`` (already there), the description.

    Raises:
        ExportError: a run can't be exported as given (the runs before it are in the dataset: run again to go on).
    """
    from rehabkit.bids.dataset import Dataset, no_participant, placement
    from rehabkit.bids.run_folder import peek_run, read_run, run_id

    peeked = {}
    for d in dirs:  # (what can be said of every run before any is read: its files, its participant)
        summary, scenario = peeked[str(d)] = peek_run(d)
        if not isinstance(scenario.get("patient"), dict) and participant is None and str(d) not in (placements or {}):
            raise no_participant(Path(d))
    added, skipped = [], []
    with Dataset(out, study) as ds:
        for d in dirs:
            t0 = time.perf_counter()
            there = ds.has(run_id(peeked[str(d)][0], Path(d)))
            if there is not None:
                skipped.append((d, there))
                say(f"skipped {d}: already in the dataset ({there})")
                continue
            run = read_run(d)
            where = (placements or {}).get(str(d)) or placement(run, participant)
            a = ds.add(run, where)
            added.append(a)
            say(f"added   {d} → {a.prefix} ({time.perf_counter() - t0:.2f} s): {_said(a)}")
        desc = ds.finish()
    return {"added": added, "skipped": skipped, "description": desc}


def export_sweep(records: list[dict[str, Any]], sweep_dir: Path, keys: list[str], out: str | Path,
                 study: dict | None = None, say=print) -> dict[str, Any]:
    """A sweep's kept runs into a dataset: each simulated person (the profile's id and the seed: ``MOD01s3``) a
    participant, each grid point a session (``ses-point<k>``, its settings as columns of ``sessions.tsv``)."""
    import yaml

    from rehabkit.bids.dataset import Placement
    from rehabkit.bids.run_folder import label

    points: dict[tuple, int] = {}
    dirs, placements = [], {}
    for rec in records:
        if rec.get("error") is not None or not rec.get("run_dir"):
            continue
        d = str((sweep_dir / rec["run_dir"]).resolve())
        point = tuple(str(rec.get(k)) for k in keys)
        k = points.setdefault(point, len(points) + 1)
        scenario = yaml.safe_load((Path(d) / "scenario.yaml").read_text()) if (Path(d) / "scenario.yaml").exists() \
            else {}
        profile = scenario.get("patient") if isinstance(scenario.get("patient"), dict) else {}
        who = f"{label(profile.get('id', '')) or 'sim'}s{rec['seed']}"
        columns = {re.sub(r"[^A-Za-z0-9]+", "_", key).strip("_"): rec.get(key) for key in keys}
        placements[d] = Placement(who, f"point{k}", columns, {c: f"the sweep's setting '{key}' at this grid point"
                                                              for c, key in zip(columns, keys)})
        dirs.append(d)
    return export_runs(dirs, out, study, placements=placements, say=say)


def cmd_export_bids(args: argparse.Namespace) -> int:
    from rehabkit.bids.run_folder import ExportError
    from rehabkit.bids.sidecars import read_study

    try:
        study = read_study(args.study) if args.study else None
        t0 = time.perf_counter()
        done = export_runs(args.run_dirs, args.out, study, args.participant)
    except ExportError as exc:
        _err(f"error: {exc}")
        return EXIT_INVALID
    runs = len(done["added"])
    print(f"wrote {args.out}: {runs} run(s) added, {len(done['skipped'])} already there "
          f"({time.perf_counter() - t0:.2f} s); `bids-validator-deno {args.out}` checks it")
    if study is None and not (Path(args.out) / ".rehabkit" / "study.json").exists():
        print("  NOTE    no --study: the dataset's authors, licence and institution are n/a (the validator warns "
              "TOO_FEW_AUTHORS); give them with --study FILE (examples/study.yaml)")
    return EXIT_OK


def cmd_progress(args: argparse.Namespace) -> int:
    from rehabkit.bids.progress import write_progress
    from rehabkit.bids.run_folder import ExportError

    try:
        page, said = write_progress(Path(args.dataset), args.participant, Path(args.out) if args.out else None)
    except ExportError as exc:
        _err(f"error: {exc}")
        return EXIT_INVALID
    for line in said:
        print(line)
    print(f"wrote {page}")
    return EXIT_OK


def add_parser(sub) -> None:
    e = sub.add_parser("export", help="finished runs in another format: bids (a Motion-BIDS dataset)")
    kinds = e.add_subparsers(dest="format", required=True)
    b = kinds.add_parser("bids", help="finished runs (with their ROS 2 bag: --bag) into a Motion-BIDS dataset; "
                                      "added to it where it exists")
    b.add_argument("run_dirs", nargs="+", metavar="RUN_DIR")
    b.add_argument("--out", required=True, metavar="DATASET", help="the dataset's folder (made, or added to)")
    b.add_argument("--participant", metavar="LABEL", help="the participant of runs without a patient profile")
    b.add_argument("--study", metavar="FILE", help="the study's name, authors, licence, institution, robots (YAML; "
                                                   "kept in the dataset for the next exports)")
    b.set_defaults(func=cmd_export_bids)
    p = sub.add_parser("progress", help="each participant's outcome measures across sessions, as an HTML page")
    p.add_argument("dataset", metavar="DATASET")
    p.add_argument("--participant", metavar="ID", help="one participant (their label or profile id)")
    p.add_argument("--out", metavar="FILE", help="the page (default: DATASET/derivatives/rehabkit/progress.html)")
    p.set_defaults(func=cmd_progress)
