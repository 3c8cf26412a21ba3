"""The fault table: each fault a drive or the bus produces, injected into HIT's six simulated CiA 402 drives at
t = 1.0 s of the round trip (mid-move, near its top speed), at 500 Hz: what the drive did (its EMCY, its states), what
the run did (the stop's reason and category), how long until the robot stood still and how far it went meanwhile.

The faults a drive produces on its own clock run on the lock-step bus (deterministic: the same figures every run);
those only the wall clock has (a host stall that starves the drives of SYNC, the interface going bus-off) in real
time, the drives in threads of this process.

    python benchmarks/canopen_faults.py
"""

from __future__ import annotations

import os
import platform
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FAULTS = [  # (fault, clock, words)
    ({"fault": "drive", "node": 2, "code": 0x2310}, "lockstep", "drive 2 over-current (its own fault)"),
    ({"fault": "drive", "node": 5, "code": 0x7305}, "lockstep", "drive 5 encoder fault"),
    ({"fault": "drive-disabled", "node": 3}, "lockstep", "drive 3 leaves OPERATION ENABLED (enable input)"),
    ({"fault": "drive-heartbeat", "node": 4}, "lockstep", "drive 4's heartbeat lost"),
    ({"fault": "drive-silent", "node": 6}, "lockstep", "drive 6 silent (no TPDO, no heartbeat)"),
    ({"fault": "host-heartbeat"}, "lockstep", "the host's heartbeat lost at the drives"),
    ({"fault": "host-stall", "for_s": 0.05}, "realtime", "the host stalls 50 ms: no SYNC"),
    ({"fault": "bus-off"}, "realtime", "the host's interface goes bus-off"),
]


def row(fault: dict, clock: str) -> dict:
    from rehabkit.api import run_scenario

    os.environ["REHABKIT_STATE"] = tempfile.mkdtemp()  # (each fault latches the robot's e-stop: a fresh latch each)
    over = {"backend": {"type": "canopen", "clock": clock, "inject": [{"at_s": 1.0, **fault}]},
            "rates": {"control_hz": 500}, "duration": 2.5}
    r = run_scenario(ROOT / "scenarios" / "hit_roundtrip.yaml", over)
    events = r.summary["safety"]["events"]
    notes = [n["text"] for n in r.summary["notes"] if n["t"] >= 1.0 - 1e-9]
    m = r.metrics
    return {"event": events[0] if events else None, "drive": [n for n in notes if n.startswith("drive")],
            "stop_time_s": m.get("stop_time_s"), "stop_distance_deg": m.get("stop_distance_deg"),
            "stop_distance_m": m.get("stop_distance_m"), "stop_peak_speed_deg_s": m.get("stop_peak_speed_deg_s")}


def main() -> None:
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
          "HIT round trip at 500 Hz on six simulated drives, each fault at t = 1.0 s")
    print("| fault | clock | the drives (EMCYs, states; first four) | the run: reason | category | detected at [s] | "
          "time to standstill [s] | largest joint travel [deg] | hand path [mm] | fastest joint after [deg/s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for fault, clock, words in FAULTS:
        r = row(fault, clock)
        ev = r["event"] or {}
        drive = "; ".join(n.split(": ", 1)[-1] if "EMCY" not in n else n for n in r["drive"][:4]) or "–"
        stop = r["stop_time_s"]
        still = "never (still moving at the end)" if stop != stop else f"{stop:.3f}"
        print(f"| {words} | {clock} | {drive} | {ev.get('cause', '–')} | {ev.get('data', {}).get('category', '–')} | "
              f"{ev.get('t', float('nan')):.3f} | {still} | {r['stop_distance_deg']:.2f} | "
              f"{1e3 * r['stop_distance_m']:.1f} | {r['stop_peak_speed_deg_s']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
