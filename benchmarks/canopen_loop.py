"""The CANopen cycle in real time between two processes, side by side with the UDP link at the same rates.

For 2, 4 and 6 drives (a horizontal DH arm of that many joints, so gravity plays no part) at 250, 500 and 1000 Hz:

- CANopen: ``rehabkit drives`` in a process of its own serving simulated CiA 402 drives on python-can's
  ``udp_multicast`` interface; this process as master (rehabkit's ``CanBus`` + ``DriveMaster``, as the canopen
  backend uses them): set-up by SDO, the 402 walk, then 4 s of cycles paced on the wall clock, a PD on a slow
  sine. Per cycle: how late the SYNC left (a cycle is late when it leaves a whole period after its deadline) and
  the time from SYNC to the cycle's last TPDO.
- UDP link: the same arm, same rate, over the hardware backend to a spawned bridge (``rehabkit bridge``), its
  round trip from command to state and its deadline misses.

With the bus arithmetic at 1 Mbit/s beside each (``rehabkit.canopen.bus.pdo_layout``): whether ``validate`` allows the
rate (udp_multicast has no bitrate: over it every combination runs). Multicast stays on loopback: the script runs
itself in a network namespace of its own (``unshare -n``, ``lo`` up, a multicast route), which needs root.

    python benchmarks/canopen_loop.py [--seconds 4]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.7"


def arm(n: int) -> dict:
    """A horizontal arm of ``n`` joints (every axis vertical) as a DH robot's settings."""
    return {"name": f"arm{n}", "convention": "standard", "table": [{"a": 0.15} for _ in range(n)],
            "joints": [{"name": f"j{k}", "range_deg": [-170, 170], "velocity_deg_s": 180, "effort": 20,
                        "mass": 0.5} for k in range(n)]}


def canopen_run(n: int, rate: float, seconds: float) -> dict:
    """The master's loop against ``rehabkit drives`` in another process: late cycles and SYNC→last TPDO [ms]."""
    from rehabkit.canopen.bus.can_bus import CanBus
    from rehabkit.canopen.config import CanopenConfig, DriveSpec
    from rehabkit.canopen.drives.limits import DriveLimits
    from rehabkit.canopen.master import DriveMaster
    from rehabkit.canopen.simulated.drive import EDS
    from rehabkit.hardware.link.clock import wait_until

    drives = subprocess.Popen([sys.executable, "-m", "rehabkit.cli", "drives", "dh", "--config", json.dumps(arm(n)),
                               "--channel", GROUP, "--duration", str(seconds + 30)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = drives.stdout.readline()
        assert line.startswith("drives:"), line + drives.stderr.read()
        period = 1.0 / rate
        clock = [0.0]
        bus = CanBus("udp_multicast", GROUP, clock=lambda: clock[0])
        units = [DriveSpec(node_id=k + 1).units(20.0) for k in range(n)]
        master = DriveMaster(bus.network, [(k + 1, str(EDS)) for k in range(n)], units,
                             [f"j{k}" for k in range(n)], CanopenConfig(), time.monotonic, [True] * n)
        try:
            wide = np.radians(175.0)
            master.configure(period, DriveLimits(np.full(n, -wide), np.full(n, wide), np.full(n, 4.0),
                                                 np.full(n, 20.0), np.full(n, 10.0), 6))
            master.place(np.zeros(n))
            deadline = [time.monotonic()]

            def paced(tau):
                wait_until(deadline[0])
                lateness = time.monotonic() - deadline[0]
                deadline[0] += period
                return master.cycle(tau, 0.8 * period), lateness

            master.enable(lambda tau: paced(tau))
            latency, late = [], []
            for k in range(int(seconds * rate)):
                ref = 0.3 * np.sin(2 * np.pi * 0.5 * k * period)
                tau = 8.0 * (ref - master.q) - 0.6 * master.qd
                lat, lateness = paced(tau)
                latency.append(lat)
                late.append(lateness)
            master.controlword[:] = 0x02  # quick stop: held, for the next run
            master.cycle(np.zeros(n), 0.8 * period)
        finally:
            bus.close()
        lat = np.array(latency) * 1e3
        got = lat[~np.isnan(lat)]
        return {"cycles": len(lat), "late": int(np.sum(np.array(late) > period)), "missed_tpdos": master.missed_total,
                "latency_median_ms": float(np.median(got)), "latency_p99_ms": float(np.percentile(got, 99)),
                "unanswered": int(np.isnan(lat).sum())}
    finally:
        drives.terminate()
        drives.wait()


def udp_run(n: int, rate: float, seconds: float, folder: Path) -> dict:
    """The same arm and rate over the UDP link to a spawned bridge: round trips and deadline misses."""
    from rehabkit.api import run_scenario

    scenario = folder / f"arm{n}_{int(rate)}.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": f"arm{n}-udp", "robot": {"type": "dh", **arm(n)},
        "backend": {"type": "hardware", "timestep": 1.0 / rate},
        "planner": {"type": "multi-cubic", "segment_durations": [seconds / 2, seconds / 2]},
        "controller": {"type": "joint-pd", "kp": [8.0] * n, "kd": [0.6] * n},
        "task": {"targets": [{"name": "A", "joints_deg": [0] * n}, {"name": "B", "joints_deg": [17] * n},
                             {"name": "C", "same_as": "A"}]},
        "duration": seconds, "rates": {"control_hz": rate}}))
    m = run_scenario(scenario).metrics
    return {"late": int(m["deadline_misses"]), "rtt_median_ms": m["rtt_median_ms"], "rtt_p99_ms": m["rtt_p99_ms"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--inside", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not args.inside:  # into a network namespace of its own: multicast on loopback only
        setup = "ip link set lo up && ip route add 224.0.0.0/4 dev lo && "
        cmd = f"{setup}{sys.executable} {Path(__file__).resolve()} --inside --seconds {args.seconds}"
        sys.exit(subprocess.call(["unshare", "-n", "sh", "-c", cmd]))
    from rehabkit.canopen.bus.pdo_layout import bus_load

    os.environ["REHABKIT_STATE"] = tempfile.mkdtemp()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
          f"{args.seconds:g} s a run; CANopen: drives in another process over udp_multicast; UDP link: a spawned "
          "bridge")
    print("| drives | rate Hz | bus load at 1 Mbit/s | validate | CANopen cycles late | SYNC→last TPDO median / p99 "
          "ms | unanswered cycles | UDP link ticks late | UDP round trip median / p99 ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n in (2, 4, 6):
            for rate in (250, 500, 1000):
                load = bus_load(n, rate, 1_000_000)
                c = canopen_run(n, rate, args.seconds)
                u = udp_run(n, rate, args.seconds, Path(tmp))
                print(f"| {n} | {rate} | {load.load:.0%} | {'allowed' if load.load <= 1 else 'refused'} | "
                      f"{c['late']} / {c['cycles']} | {c['latency_median_ms']:.2f} / {c['latency_p99_ms']:.2f} | "
                      f"{c['unanswered']} | {u['late']} | {u['rtt_median_ms']:.2f} / {u['rtt_p99_ms']:.2f} |",
                      flush=True)


if __name__ == "__main__":
    main()
