"""kill -9 at random moments of a 60 s session: how much each file lost, and whether ``rehabkit recover`` made a run
folder of what was left.

    python benchmarks/kill_recovery.py [--tries 20] [--scenario scenarios/lexos_myoarm.yaml]

Each try runs ``rehabkit run SCENARIO --bag --set duration=60`` and SIGKILLs it at a random moment of its loop (after
its recording's file appears). The gap of a file is the wall time between the kill and the file's last write on disk
(its modification time), and in the run's own time: where the run stood at the kill (estimated: the latest file's
last time, plus the wall time since it was written times the run's real-time factor so far) less the last time the
file holds (as ``rehabkit recover`` reads it back). The safety log is written only when there is something to record
(its trips before the stop acts, routine records within a second), so it is said with what it holds. Then
``rehabkit recover``.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def one(out: Path, scenario: Path, rng: random.Random) -> dict:
    cmd = [sys.executable, "-m", "rehabkit.cli", "run", str(scenario), "--out", str(out), "--bag", "--set",
           "duration=60"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    tmp = out / "run.rrd.tmp"
    while not tmp.exists() and proc.poll() is None:
        time.sleep(0.01)
    opened = time.time()
    time.sleep(rng.uniform(0.2, 6.0))  # (a random moment of the loop: what is measured is the wall clock's)
    killed = time.time()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    gaps = {}
    for name in ("run.rrd.tmp", ".run.mcap.part", "safety_log.jsonl"):
        path = out / name
        gaps[name] = killed - path.stat().st_mtime if path.exists() else None
    rec = subprocess.run([sys.executable, "-m", "rehabkit.cli", "recover", str(out)], capture_output=True, text=True,
                         cwd=ROOT)
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    recovered = summary.get("recovered", {})
    until = {"run.rrd.tmp": recovered.get("recording_until_s"), ".run.mcap.part": recovered.get("bag_until_s")}
    # where the run stood at the kill: the latest-written file's last time, on at the run's pace so far
    known = [(until[n], gaps[n]) for n in until if until[n] is not None and gaps[n] is not None]
    sim_gaps = {}
    if known:
        last, gap = max(known, key=lambda x: x[0])
        rtf = last / max(1e-3, killed - gap - opened)
        at_kill = last + gap * rtf
        sim_gaps = {n: at_kill - until[n] for n in until if until[n] is not None}
    log = [json.loads(line) for line in (out / "safety_log.jsonl").read_text().splitlines() if line.strip()] \
        if (out / "safety_log.jsonl").exists() else []
    log_t = max((r["t"] for r in log if isinstance(r.get("t"), (int, float))), default=None)
    return {"gaps": gaps, "sim_gaps": sim_gaps, "recover": rec.returncode, "recovered": recovered,
            "log_records": recovered.get("safety_log_records"), "log_t": log_t,
            "bag_topics": sorted(recovered.get("bag_messages", {}))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tries", type=int, default=20)
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "lexos_myoarm.yaml"))
    args = ap.parse_args()
    rng = random.Random(0)
    base = Path(tempfile.mkdtemp(prefix="kill-"))
    rows = [one(base / f"try{i:02d}", Path(args.scenario), rng) for i in range(args.tries)]
    print(f"{args.tries} tries of kill -9 on {Path(args.scenario).name} (60 s sessions, --bag); load "
          f"{os.getloadavg()[0]:.2f}; folders in {base}\n")
    print(f"{'try':>4} {'rrd gap s':>10} {'bag gap s':>10} {'log gap s':>10} {'rrd sim gap':>12} {'bag sim gap':>12} "
          f"{'recover':>8} {'recording until':>16} {'bag until':>10} {'log records':>11} {'log last t':>10}")
    fmt = lambda v: "—" if v is None else f"{v:.3f}"  # noqa: E731
    for i, r in enumerate(rows):
        g, sg, rec = r["gaps"], r["sim_gaps"], r["recovered"]
        print(f"{i:4d} {fmt(g['run.rrd.tmp']):>10} {fmt(g['.run.mcap.part']):>10} {fmt(g['safety_log.jsonl']):>10} "
              f"{fmt(sg.get('run.rrd.tmp')):>12} {fmt(sg.get('.run.mcap.part')):>12} "
              f"{r['recover']:>8} {fmt(rec.get('recording_until_s')):>16} {fmt(rec.get('bag_until_s')):>10} "
              f"{r['log_records'] or '—':>11} {fmt(r['log_t']):>10}")
    for name in ("run.rrd.tmp", ".run.mcap.part"):
        worst = max((r["gaps"][name] for r in rows if r["gaps"][name] is not None), default=None)
        worst_sim = max((r["sim_gaps"][name] for r in rows if name in r["sim_gaps"]), default=None)
        print(f"largest gap, {name}: {fmt(worst)} s of wall time, {fmt(worst_sim)} s of the run's time (estimated)")
    topics = sorted({t for r in rows for t in r["bag_topics"]})
    print(f"the recovered bags' topics: {', '.join(topics) or 'none'}")
    print(f"recovered: {sum(r['recover'] == 0 for r in rows)} of {len(rows)}")


if __name__ == "__main__":
    main()
