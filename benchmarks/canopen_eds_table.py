"""Every real drive's EDS/DCF in tests/data/canopen_eds/ under the CANopen master, as a lab would try it: HIT with six
drives of that file (a DCF written for node 1 on drive 1 only, the others the generic servo), `rehabkit validate`
and `rehabkit run` as processes (their exit codes, or the refusal verbatim), the run's tracking against MuJoCo's at the
same rate, and what the set-up wrote into drive 1 by SDO, decoded from the run's CAN trace as any CAN tool reads it.

    python benchmarks/canopen_eds_table.py [--duration S] [--json benchmarks/results/canopen_eds_table.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import can
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
EDS = ROOT / "tests" / "data" / "canopen_eds"
FILES = [("SIMULATED_ros2canopen_cia402_slave.eds", "cst"), ("SIMULATED_ros2canopen_cia402_slave.eds", "csp"),
         ("elmo_Gold-Drive.dcf", "cst"), ("faulhaber_MCLM300x-CO.eds", "cst"), ("maxon_EPOS4-Module-50-5.eds", "cst"),
         ("maxon_EPOS4-Module-50-15_node1.dcf", "cst"), ("nanotec_C5-E-2-09.eds", "cst"),
         ("zeroerr_eDriver-V1.5.eds", "cst")]


def sdo_writes(trace: Path, node: int = 1) -> list[str]:
    """The expedited SDO downloads to ``node`` the drive confirmed, as ``index:sub=value``, in order."""
    out, pending = [], None
    for f in can.LogReader(trace):
        if f.arbitration_id == 0x600 + node and f.data[0] & 0xE3 in (0x23, 0x27, 0x2B, 0x2F):
            size = 4 - (f.data[0] >> 2 & 3)
            pending = (int.from_bytes(f.data[1:3], "little"), f.data[3], int.from_bytes(f.data[4:4 + size], "little"))
        elif f.arbitration_id == 0x580 + node and pending and f.data[0] == 0x60:
            out.append(f"{pending[0]:04X}:{pending[1]}={pending[2]:#x}")
            pending = None
        elif f.arbitration_id == 0x580 + node and f.data[0] == 0x80:
            pending = None
    return out


def row(name: str, mode: str, duration: float, work: Path, sims: dict) -> dict:
    rate = 500 if mode == "cst" else 250
    drives = [{"node_id": k, "eds": str(EDS / name), "mode": mode} for k in range(1, 7)]
    if "node1" in name:
        drives = [drives[0]] + [{"node_id": k} for k in range(2, 7)]
    scenario = work / f"{name}-{mode}.yaml"
    scenario.write_text(yaml.safe_dump({"extends": str(ROOT / "scenarios" / "hit_roundtrip.yaml"),
                                        **({"duration": duration, "expect": {"task_complete": {"eq": 0}}}
                                           if duration else {}), "rates": {"control_hz": rate},
                                        "backend": {"type": "canopen", "clock": "lockstep", "drives": drives,
                                                    "other_pdos": "disable"}}))
    env = {**os.environ, "REHABKIT_STATE": str(work / "state")}
    cli = [sys.executable, "-m", "rehabkit.cli"]
    v = subprocess.run([*cli, "validate", str(scenario)], capture_output=True, text=True, env=env)
    out = {"file": name, "mode": mode, "validate": v.returncode,
           "refusal": v.stderr.strip().splitlines()[0] if v.returncode else ""}
    if v.returncode:
        return out
    run_dir = work / f"{name}-{mode}"
    r = subprocess.run([*cli, "run", str(scenario), "--out", str(run_dir)], capture_output=True, text=True, env=env)
    out["run"] = r.returncode
    summary = json.loads((run_dir / "summary.json").read_text())
    from rehabkit.api import run_scenario
    from rehabkit.core.safety.estop import own_state

    with own_state(work / "state-again"):  # (the same run in this process, for its joint trace)
        q = run_scenario(scenario).trace.q
    m = summary["metrics"]
    out.update({"tracking_rms_deg": m.get("tracking_rms_deg"), "can_emcy": m.get("can_emcy"),
                "safety_events": m.get("safety_events"), "notes": [n["text"] for n in summary["notes"]][:2],
                "sdo_writes_drive1": sdo_writes(run_dir / "can.asc")})
    out["max_dev_from_mujoco_deg"] = float(np.degrees(np.abs(sims[rate][: len(q)] - q)).max())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=None, help="cut the HIT short [s] (default: its whole task)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "canopen_eds_table.json"))
    args = ap.parse_args()
    from rehabkit.api import run_scenario
    from rehabkit.core.safety.estop import own_state

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        with own_state(work / "sim-state"):
            cut = {"duration": args.duration} if args.duration else {}
            sims = {rate: run_scenario(ROOT / "scenarios" / "hit_roundtrip.yaml",
                                       {"rates": {"control_hz": rate}, **cut}).trace.q
                    for rate in (250, 500)}
        rows = [row(name, mode, args.duration, work, sims) for name, mode in FILES]
    for r in rows:
        if r["validate"]:
            print(f"{r['file']:40s} {r['mode']}  validate {r['validate']}: {r['refusal']}")
        else:
            print(f"{r['file']:40s} {r['mode']}  validate 0  run {r['run']}  rms {r['tracking_rms_deg']:.3f}°  "
                  f"vs MuJoCo {r.get('max_dev_from_mujoco_deg', float('nan')):.4f}°  EMCY {r['can_emcy']}")
            print(f"{'':44s} wrote: {' '.join(r['sdo_writes_drive1'])}")
    Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
