"""Every way a run can end, and what its folder holds after: the files, the safety log's audit, the recording opened
with the Rerun SDK and the bag with rosbags (the last time each holds), the exit code.

    python benchmarks/endings_table.py [--out DIR]

Each ending is a ``rehabkit run`` process (``--bag``), as a user meets it: completed (the HIT round trip), a safety
stop (``scenarios/safety/hit_range.yaml``), Ctrl-C and SIGTERM sent to the process 2 s into its loop, a plugin's
fault and a backend's fault (the process's MuJoCo backend made to raise at 1.5 s of simulated time), the link lost
(``scenarios/safety/hit_link_loss.yaml``), and kill -9 (then ``rehabkit recover``, where the command exists).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HIT, RANGE, LOSS = (ROOT / "scenarios" / p for p in ("hit_roundtrip.yaml", "safety/hit_range.yaml",
                                                      "safety/hit_link_loss.yaml"))
# a process whose MuJoCo backend raises at 1.5 s of simulated time (a plugin's bug / a backend's fault)
FAULTY = """
import sys
from rehabkit.sim.mujoco import MujocoBackend
from rehabkit.core.kinds.backend import BackendFaultError
real, kind = MujocoBackend.step, sys.argv.pop(1)
def step(self, n=1):
    if self.data.time >= 1.5:
        raise (ZeroDivisionError("a plugin's bug") if kind == "plugin" else BackendFaultError("the bus went away"))
    real(self, n)
MujocoBackend.step = step
from rehabkit.cli.main import main
sys.exit(main())
"""


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "rehabkit.cli", *args]


def _run(cmd: list[str], signal_after: float | None = None, sig: int = signal.SIGINT) -> int:
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    if signal_after is not None:
        time.sleep(signal_after)  # (a user's Ctrl-C comes at a moment of their choosing: wall time is the point here)
        proc.send_signal(sig)
    return proc.wait(timeout=300)


def _recording_end(path: Path) -> str:
    """The last simulated time of the joints' series the recording holds, read with the Rerun SDK."""
    if not path.exists():
        return "—"
    from rerun.chunk import RrdReader

    try:
        last = None
        for chunk in RrdReader(str(path)).stream().to_chunks():
            if "sim_time" in chunk.timeline_names and str(chunk.entity_path).startswith("/joints"):
                ns = chunk.to_record_batch().column("sim_time").cast("int64").to_numpy()
                last = max(last or 0, int(ns.max())) if len(ns) else last
        return f"{last / 1e9:.3f} s" if last is not None else "empty"
    except Exception as exc:  # noqa: BLE001 (said in the table)
        return f"unreadable ({type(exc).__name__}: {exc})"[:80]


def _bag_end(path: Path) -> str:
    if not path.exists():
        return "—"
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([path]) as reader:
            last = max((stamp for _, stamp, _ in reader.messages()), default=None)
            first = reader.start_time
        return f"{(last - first) / 1e9:.3f} s" if last is not None else "empty"
    except Exception as exc:  # noqa: BLE001 (said in the table)
        return f"unreadable ({type(exc).__name__})"


def _audit(out: Path) -> str:
    r = subprocess.run(_cli("audit", str(out)), capture_output=True, text=True, cwd=ROOT)
    said = (r.stdout + r.stderr).strip().splitlines()
    verdict = next((line.strip() for line in reversed(said) if "chain" in line or "unfinished" in line), said[-1:])
    return f"exit {r.returncode}: {verdict}"


def row(name: str, out: Path, code: int) -> dict:
    files = sorted(p.name for p in out.iterdir()) if out.exists() else []
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    ended = summary.get("ended", {})
    return {"ending": name, "exit": code, "files": ", ".join(files) or "none",
            "ended": f"{ended.get('how', '—')}" + (f" ({ended['reason'][:60]})" if ended.get("reason") else ""),
            "audit": _audit(out) if (out / "safety_log.jsonl").exists() else "no log",
            "recording": _recording_end(out / "run.rrd"), "bag": _bag_end(out / "run.mcap"),
            "sim_time": f"{summary['metrics']['sim_time_s']:.3f} s" if summary else "—"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    base = args.out or Path(tempfile.mkdtemp(prefix="endings-"))
    long = ["--set", "duration=300"]  # (a session the signal comes well inside of: 2 s of wall time into it)
    cases = [
        ("completed", lambda o: _run(_cli("run", str(HIT), "--out", str(o), "--bag"))),
        ("safety stop", lambda o: _run(_cli("run", str(RANGE), "--out", str(o), "--bag"))),
        ("Ctrl-C", lambda o: _run(_cli("run", str(HIT), "--out", str(o), "--bag", *long), 3.0, signal.SIGINT)),
        ("SIGTERM", lambda o: _run(_cli("run", str(HIT), "--out", str(o), "--bag", *long), 3.0, signal.SIGTERM)),
        ("plugin fault", lambda o: _run([sys.executable, "-c", FAULTY, "plugin", "run", str(HIT), "--out", str(o),
                                         "--bag"])),
        ("backend fault", lambda o: _run([sys.executable, "-c", FAULTY, "backend", "run", str(HIT), "--out", str(o),
                                          "--bag"])),
        ("link lost", lambda o: _run(_cli("run", str(LOSS), "--out", str(o), "--bag"))),
        ("kill -9", lambda o: _run(_cli("run", str(HIT), "--out", str(o), "--bag", *long), 3.0, signal.SIGKILL)),
    ]
    rows = []
    for name, run in cases:
        out = base / name.replace(" ", "_").replace("-", "")
        code = run(out)
        rows.append(row(name, out, code))
        if name == "kill -9":
            rec = subprocess.run(_cli("recover", str(out)), capture_output=True, text=True, cwd=ROOT)
            rows.append(row(f"kill -9, then recover (exit {rec.returncode})", out, code))
    keys = list(rows[0])
    print(f"outputs in {base}; load {os.getloadavg()[0]:.2f}\n")
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(str(r[k]) for k in keys) + " |")


if __name__ == "__main__":
    main()
