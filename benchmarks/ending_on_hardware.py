"""The robot's state after SIGTERM on the link and on CANopen (issue 48's closing note): the HIT round trip run in a
process of its own on each backend (simulated CiA 402 drives on a virtual CAN bus; the hardware link to a bridge it
starts), SIGTERM sent to that process from outside once its loop runs, as a service manager sends it. Printed: its
exit code and ``ended``, the safety layer's event, the joints' last speeds, then on CANopen each drive's CiA 402 and
NMT state and its heartbeat consumer of the host (0x1016:1), read from the simulated drives, and the last frames on
the bus decoded from the run's CAN trace with canopen's own tables; over the link the bridge's last state (its status
bits) and its process.

    python benchmarks/ending_on_hardware.py [--clock lockstep|realtime] [--after S] [--json FILE]
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

ROOT = Path(__file__).resolve().parents[1]
HIT = ROOT / "scenarios" / "hit_roundtrip.yaml"
OVER = {"canopen": {"backend": {"type": "canopen"}, "rates": {"control_hz": 500}},
        "hardware": {"backend": {"type": "hardware"}}}


def child(kind: str, clock: str, out: Path) -> int:
    """The run, in this process: 'loop' said on stdout as it starts, the hardware's state as JSON at its end."""
    import numpy as np

    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    over = {**OVER[kind], "backend": {**OVER[kind]["backend"], "clock": clock}}
    runner = Runner(load_scenario(HIT, over), out_dir=out)
    result = runner.run(prepare=lambda session: print("loop", flush=True))
    b = runner.setup.backend
    k = round(result.ending.t / runner.setup.schedule.control_dt)  # (the step the signal came at)
    state = {"fastest_joint_at_the_signal_deg_s": round(float(np.degrees(np.abs(result.trace.qd[k - 1]).max())), 2),
             "steps_after_the_signal": len(result.trace.qd) - k,
             "q_deg": np.degrees(result.trace.q[-1]).round(3).tolist(),
             "qd_deg_s": np.degrees(result.trace.qd[-1]).round(4).tolist()}
    if kind == "canopen":
        state["drives"] = [{"node": d.node.id, "cia402": d.machine.state.name, "nmt": d.nmt.state,
                            "0x1016:1": d.node.sdo[0x1016][1].raw} for d in b.rig.drives]
    else:
        from rehabkit.hardware.link import protocol as p

        bits = [name for name in ("ENABLED", "HOLDING", "ESTOPPED", "WATCHDOG", "STALE", "LIMIT", "RAMP_IN",
                                  "CLEARED", "TICK") if b.status & getattr(p, name)]
        state["bridge"] = {"pid": b.process.pid, "returncode": b.process.returncode, "last_status": bits,
                           "q_deg": np.degrees(b.q).round(3).tolist(), "qd_deg_s": np.degrees(b.qd).round(4).tolist()}
    print("state " + json.dumps(state), flush=True)
    return result.exit_code


def _statusword(word: int) -> str:
    from canopen.profiles.p402 import State402

    return next(n for n, (mask, value) in State402.SW_MASK.items() if word & mask == value)


def _frame(f) -> str:
    """A frame as a CAN tool shows it, decoded by canopen's tables."""
    from canopen.nmt import NMT_COMMANDS, NMT_STATES

    i, d = f.arbitration_id, bytes(f.data)
    what = ""
    if i == 0x000:
        what = f"NMT {dict((v, k) for k, v in NMT_COMMANDS.items()).get(d[0], hex(d[0]))} node {d[1]}"
    elif i == 0x080:
        what = "SYNC"
    elif 0x181 <= i <= 0x1FF:
        what = f"TPDO1 node {i - 0x180}: statusword 0x{int.from_bytes(d[:2], 'little'):04x} " \
               f"{_statusword(int.from_bytes(d[:2], 'little'))}"
    elif 0x281 <= i <= 0x2FF:
        what = f"TPDO2 node {i - 0x280}"
    elif 0x201 <= i <= 0x27F:
        what = f"RPDO1 node {i - 0x200}: controlword 0x{d[0]:02x}" if len(d) > 2 else f"RPDO1 node {i - 0x200}"
    elif 0x601 <= i <= 0x67F:
        what = f"SDO to node {i - 0x600}: 0x{d[1] | d[2] << 8:04x}:{d[3]} = {int.from_bytes(d[4:], 'little')}"
    elif 0x581 <= i <= 0x5FF:
        what = f"SDO answer node {i - 0x580}: 0x{d[0]:02x}"
    elif 0x701 <= i <= 0x77F:
        what = f"heartbeat node {i - 0x700}: {NMT_STATES.get(d[0], hex(d[0]))}"
    return f"{f.timestamp:8.3f}  {i:03X}  {d.hex(' '):23s}  {what}"


def ending(kind: str, clock: str, after: float) -> dict:
    out = Path(tempfile.mkdtemp(prefix=f"ending-{kind}-"))
    proc = subprocess.Popen([sys.executable, __file__, "--child", kind, "--clock", clock, "--out", str(out)],
                            stdout=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stdout.readline().strip() == "loop"
    time.sleep(after)
    os.kill(proc.pid, signal.SIGTERM)
    sent = time.monotonic()
    lines = proc.stdout.read().splitlines()
    code = proc.wait()
    state = json.loads(next(x for x in lines if x.startswith("state "))[6:])
    summary = json.loads((out / "summary.json").read_text())
    figures = {"backend": kind, "clock": clock, "exit_code": code, "ended": summary["ended"],
               "events": [{k: e[k] for k in ("rule", "t", "message")} | {"category": e["data"].get("category")}
                          for e in summary["safety"]["events"]],
               "sigterm_to_exit_s": round(time.monotonic() - sent, 3), "files": sorted(p.name for p in out.iterdir()),
               **state}
    if kind == "canopen":
        import can

        frames = list(can.LogReader(out / "can.asc"))
        figures["last_frames"] = [_frame(f) for f in frames[-40:]]
        ids = [f.arbitration_id for f in frames]
        figures["frames_after_last_nmt"] = len(frames) - 1 - max(k for k, i in enumerate(ids) if i == 0)
    else:
        try:
            os.kill(state["bridge"]["pid"], 0)
            figures["bridge_process"] = "still there"
        except ProcessLookupError:
            figures["bridge_process"] = "gone"
    return figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clock", default="lockstep", choices=["lockstep", "realtime"])
    ap.add_argument("--after", type=float, default=0.5, help="wall seconds into the loop the SIGTERM comes")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        sys.exit(child(args.child, args.clock, args.out))
    results = []
    for kind in ("canopen", "hardware"):
        fig = ending(kind, args.clock, args.after)
        results.append(fig)
        print(f"== {kind} ({args.clock}): SIGTERM {args.after:g} s (wall) into the loop")
        for k, v in fig.items():
            if k == "last_frames":
                print("last frames on the bus (time [s], id, data, decoded):")
                print("\n".join("  " + x for x in v))
            elif k == "drives":
                for d in v:
                    print(f"  drive {d['node']}: {d['cia402']}, NMT {d['nmt']}, 0x1016:1 = {d['0x1016:1']}")
            else:
                print(f"{k}: {v}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
