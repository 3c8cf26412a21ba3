"""The README's two-process CANopen run, again and again: how often it completes, quiet and with one core busy.

Runs exactly the command in the README's "On CANopen drives" section (``rehabkit drives hit`` and ``rehabkit run
scenarios/hit_roundtrip.yaml`` at 500 Hz over udp_multicast, in a network namespace of its own: ``unshare -n``, as
root), with ``--out DIR`` added, ``--runs`` times quiet and then ``--runs`` times with one core kept busy (a busy-loop
process for the whole series), side by side in one invocation so the two are comparable. Per series: runs completed
(exit 0, ``can_cycles`` 4250, no safety event), each failure's reason (the summary's first safety event, else
stderr's last line), the host's late steps and hold cycles (``can_late_cycles``, ``can_hold_cycles``), EMCYs, the
SYNC→last-TPDO latency p99, and the drives' own figures (their stderr line: the largest gap between SYNCs as they
arrived, SYNCs handled a cycle late, their watchdog's worst wake-up and what it fired for). Before each series, what
the OS stalls a process by there: a thread sleeping 1 ms at a time, its worst oversleep.

``--ab`` runs the series again (``--ab-runs`` times each) per set of deadline measures (``REHABKIT_DEADLINES``, in
both processes: :mod:`rehabkit.canopen.deadlines`), for their A/B against the kept ones. Each run has a time limit
(``--timeout``); the busy loop ends with the series. Results: a Markdown table, and JSON in
``benchmarks/results/canopen_two_process.json``.

    python benchmarks/canopen_two_process.py [--runs 20] [--ab fifo gc none gc,fifo,affinity --ab-runs 5]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CYCLES = 4250  # the scenario's 8.5 s at 500 Hz
DRIVES = re.compile(r"drives: (\d+) cycles; SYNC gap max ([\d.]+) ms .*?; (\d+) SYNCs handled a cycle or more late "
                    r"\(max ([\d.]+) ms\); watchdog woke up to ([\d.]+) ms late, waited (\d+) times for unread frames, "
                    r"fired (\d+) times(?:: ([^;]*))?")
SLEEPER = """
import time
worst, end = 0.0, time.monotonic() + {seconds}
while time.monotonic() < end:
    t = time.monotonic(); time.sleep(0.001); worst = max(worst, time.monotonic() - t - 0.001)
print(worst * 1e3)
"""


def readme_command(out: Path) -> str:
    """The README's two-process command (its CANopen section's third code block), its run writing into ``out``."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## On CANopen drives"):readme.index("## Benchmarks")]
    command = re.findall(r"```(\w+)\n(.*?)```", section, re.S)[2][1].strip()
    assert command.startswith("unshare -n sh -c '") and "; RC=$?" in command, command
    return command.replace("; RC=$?", f" --out {out}; RC=$?")


def run_once(out: Path, env: dict, timeout: float) -> dict:
    """One run of the README's command: its outcome, the host's figures and the drives'."""
    t0 = time.monotonic()
    p = subprocess.Popen(readme_command(out), shell=True, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        _, err = p.communicate()
        return {"rc": None, "completed": False, "reason": f"timed out after {timeout:g} s", "seconds": timeout}
    except BaseException:  # (the benchmark stopped: its run with it)
        os.killpg(p.pid, signal.SIGKILL)
        raise
    row: dict = {"rc": p.returncode, "seconds": round(time.monotonic() - t0, 1)}
    lines = [x for x in re.split(r"[\r\n]", err) if x.strip() and "step/s" not in x and not x.startswith("drives:")]
    summary = out / "summary.json"
    events = []
    if summary.exists():
        s = json.loads(summary.read_text())
        m, events = s["metrics"], s["safety"]["events"]
        row.update({k: m.get(k) for k in ("can_cycles", "can_late_cycles", "can_hold_cycles", "can_emcy",
                                          "can_missed_tpdos", "can_latency_p99_ms")})
    row["completed"] = p.returncode == 0 and row.get("can_cycles") == CYCLES and not events
    if not row["completed"]:
        row["reason"] = events[0]["message"] if events else (lines[-1] if lines else f"exit {p.returncode}")
    if not row["completed"]:  # (the drives' own line as it was, for the failure's story)
        row["drives_said"] = (re.search(r"drives: \d+ cycles.*", err) or [""])[0]
    if (d := DRIVES.search(err)) is not None:
        row["drives"] = {"cycles": int(d[1]), "max_sync_gap_ms": float(d[2]), "late_syncs": int(d[3]),
                         "max_sync_delay_ms": float(d[4]), "watchdog_woke_late_ms": float(d[5]),
                         "watchdog_waited": int(d[6]), "fired": int(d[7]), "fired_for": d[8] or ""}
    return row


def stall(seconds: float) -> float:
    """The worst oversleep [ms] of a thread sleeping 1 ms at a time for ``seconds``, in a process of its own."""
    out = subprocess.run([sys.executable, "-c", SLEEPER.format(seconds=seconds)], capture_output=True, text=True)
    return round(float(out.stdout), 2)


def series(runs: int, measures: str, busy: bool, timeout: float, stall_s: float, work: Path) -> dict:
    """``runs`` runs with ``measures`` (REHABKIT_DEADLINES), one core kept busy meanwhile or not."""
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if busy else None
    try:
        time.sleep(0.5 if busy else 0.0)  # (the busy loop running before anything is measured)
        load = os.getloadavg()
        slept = stall(stall_s) if stall_s > 0 else None
        rows = []
        for k in range(runs):
            out = work / f"{measures}-{'busy' if busy else 'quiet'}-{k}"
            state = work / f"state-{out.name}"  # (a run a safety event stopped latches the e-stop: its own)
            env = {**os.environ, "REHABKIT_DEADLINES": measures, "REHABKIT_STATE": str(state)}
            rows.append(run_once(out, env, timeout))
            r = rows[-1]
            print(f"  {measures} {'busy' if busy else 'quiet'} {k + 1}/{runs}: "
                  f"{'ok' if r['completed'] else 'FAILED: ' + r['reason']}", file=sys.stderr, flush=True)
        load_end = os.getloadavg()
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
    return aggregate(rows, measures, busy, slept, (load[0], load_end[0]))


def aggregate(rows: list[dict], measures: str, busy: bool, slept: float | None, load: tuple[float, float]) -> dict:
    def values(key: str, side: str | None = None) -> list[float]:
        return [(r.get(side) or {}).get(key) if side else r.get(key) for r in rows
                if ((r.get(side) or {}).get(key) if side else r.get(key)) is not None]

    p99 = values("can_latency_p99_ms")
    gaps = values("max_sync_gap_ms", "drives")
    return {"measures": measures, "busy": busy, "runs": len(rows), "completed": sum(r["completed"] for r in rows),
            "failures": [r["reason"] for r in rows if not r["completed"]],
            "late_cycles": sum(values("can_late_cycles")), "hold_cycles": sum(values("can_hold_cycles")),
            "late_cycles_max": max(values("can_late_cycles"), default=None), "emcy": sum(values("can_emcy")),
            "missed_tpdos": sum(values("can_missed_tpdos")),
            "latency_p99_ms_median": round(statistics.median(p99), 2) if p99 else None,
            "latency_p99_ms_max": round(max(p99), 2) if p99 else None,
            "drives_max_sync_gap_ms": max(gaps, default=None),
            "drives_sync_gap_ms_median": round(statistics.median(gaps), 1) if gaps else None,
            "drives_late_syncs": sum(values("late_syncs", "drives")),
            "drives_watchdog_woke_late_ms": max(values("watchdog_woke_late_ms", "drives"), default=None),
            "drives_watchdog_fired": sum(values("fired", "drives")),
            "drives_fired_for": sorted({r["drives"]["fired_for"] for r in rows if r.get("drives", {}).get("fired")}),
            "sleeper_worst_oversleep_ms": slept, "load_1min": [round(x, 2) for x in load], "rows": rows}


def table(results: list[dict]) -> str:
    head = ("| measures | one core busy | completed | late steps (max a run) | hold cycles | EMCYs | missed TPDOs | "
            "SYNC→last TPDO p99 median / max ms | drives: SYNC gap max (median a run) ms | drives: SYNCs handled "
            "late | drives: watchdog woke late ms / fired | 1 ms sleeper overslept ms | load |\n" + "|---" * 13 + "|")
    lines = [head]
    for s in results:
        lines.append(
            f"| {s['measures']} | {'yes' if s['busy'] else 'no'} | {s['completed']} of {s['runs']} | "
            f"{s['late_cycles']:g} ({s['late_cycles_max']}) | {s['hold_cycles']:g} | {s['emcy']:g} | "
            f"{s['missed_tpdos']:g} | {s['latency_p99_ms_median']} / {s['latency_p99_ms_max']} | "
            f"{s['drives_max_sync_gap_ms']} ({s['drives_sync_gap_ms_median']}) | {s['drives_late_syncs']} | "
            f"{s['drives_watchdog_woke_late_ms']} / {s['drives_watchdog_fired']} | {s['sleeper_worst_oversleep_ms']} | "
            f"{s['load_1min'][0]}–{s['load_1min'][1]} |")
    for s in results:
        for reason in dict.fromkeys(s["failures"]):
            lines.append(f"- {s['measures']}, {'busy' if s['busy'] else 'quiet'}: {s['failures'].count(reason)}× "
                         f"{reason}")
    return "\n".join(lines)


def main() -> None:
    from rehabkit.canopen.deadlines import KEPT, SYNC_TIMEOUT_MS

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20, help="runs per series (quiet, then one core busy)")
    ap.add_argument("--variants", nargs="*", default=[KEPT], help="REHABKIT_DEADLINES values, --runs each")
    ap.add_argument("--ab", nargs="*", default=[], help="more REHABKIT_DEADLINES values to compare, --ab-runs each "
                    "(e.g. fifo gc none gc,fifo,affinity: each measure left out, or added)")
    ap.add_argument("--ab-runs", type=int, default=5)
    ap.add_argument("--timeout", type=float, default=90.0, help="a run's time limit [s]")
    ap.add_argument("--stall-seconds", type=float, default=10.0, help="the 1 ms sleeper's time before each series")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "canopen_two_process.json"))
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # (stopped: the busy loop stopped too, in its finally)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for runs, variants in ((args.runs, args.variants), (args.ab_runs, args.ab)):
            for measures in variants:
                for busy in (False, True):
                    results.append(series(runs, measures, busy, args.timeout, args.stall_seconds, Path(tmp)))
    head = (f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
            f"the README's two-process run, {args.runs} times a series ({args.ab_runs} for the A/B); uid "
            f"{os.getuid()}; drives' SYNC watchdog {SYNC_TIMEOUT_MS:g} ms")
    print(head)
    print(table(results))
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps({"machine": head, "series": results}, indent=1))


if __name__ == "__main__":
    main()
