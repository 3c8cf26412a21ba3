"""``rehabkit drives``: simulated CiA 402 drives for a robot on a CAN bus — one per joint, on the robot's MuJoCo model
— for everyone without the robot: a canopen backend with ``bus: {interface, channel, simulated: true}`` drives them
as it would the robot's own."""

from __future__ import annotations

import argparse
import gc
import json
import signal
import sys
import threading
import time
from collections import Counter

from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS
from rehabkit.cli.exits import EXIT_INVALID, EXIT_OK


def _err(msg: str) -> None:
    print(msg, file=sys.stderr)


def cmd_drives(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np
    from pydantic import TypeAdapter, ValidationError

    from rehabkit.canopen.config import DriveSpec
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry

    try:
        info = default_registry().get("robot", args.robot)
        here = Context(Path.cwd(), np.random.default_rng(args.seed), args.timestep)
        robot = info.factory(info.config.model_validate({**json.loads(args.config), "type": args.robot}), here)
    except ValidationError as exc:
        wrong = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'config'}: {e['msg']}" for e in exc.errors())
        _err(f"error: --config: robot '{args.robot}': {wrong} (its settings as the scenario's robot section has "
             "them, as JSON; `rehabkit plugins --fields " + args.robot + "` lists them)")
        return EXIT_INVALID
    except (ValueError, KeyError, OSError) as exc:
        _err(f"error: robot '{args.robot}' cannot be built from --config: {exc} (files relative to {Path.cwd()})")
        return EXIT_INVALID
    dof = robot.model.dof
    try:
        specs = TypeAdapter(list[DriveSpec]).validate_json(args.drives) if args.drives else [
            DriveSpec(node_id=i + 1) for i in range(dof)]
    except ValidationError as exc:
        wrong = "; ".join(f"drive {'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        _err(f"error: --drives: {wrong}")
        return EXIT_INVALID
    ids = [s.node_id for s in specs]
    if len(specs) != dof or len(set(ids)) != dof:
        twice = sorted({i for i in ids if ids.count(i) > 1})
        _err(f"error: --drives: robot '{robot.model.name}' has {dof} joints ({', '.join(robot.model.joint_names)}): "
             f"{len(specs)} drives given" + (f", node id {twice[0]} twice" if twice else "") +
             "; one drive per joint, in that order, node ids unique (the scenario's backend.drives)")
        return EXIT_INVALID
    import canopen

    from rehabkit.canopen import deadlines
    from rehabkit.canopen.drives.units import units_of
    from rehabkit.canopen.simulated.rig import DriveRig
    from rehabkit.hardware.plant import MujocoPlant

    kw = {"interface": args.interface, "channel": args.channel, "receive_own_messages": False}
    if args.interface not in ("virtual", "udp_multicast"):
        kw["bitrate"] = args.bitrate
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.1  # (its reader's wait for a frame: the wait of its stop, 1 s by default, at the end)
    network.connect(**kw)
    try:
        plant = MujocoPlant(robot, args.timestep)
        effort = robot.model.limits.effort
        from rehabkit.canopen.simulated.drive import EDS

        eds = [Path(s.eds) if s.eds else EDS for s in specs]  # (each drive serves its own EDS/DCF, as the robot's)
        units = [units_of(s, effort[i], str(path)) for i, (s, path) in enumerate(zip(specs, eds, strict=True))]
        rig = DriveRig(network, plant, [s.node_id for s in specs], units, eds=eds)
        rig.reset(np.clip(np.zeros(dof), robot.model.limits.lower, robot.model.limits.upper))
        watchdog = rig.watch_sync(args.sync_timeout_ms * 1e-3)
        had = deadlines.pin("drives")
        deadlines.hold_collector()
        sys.setswitchinterval(5e-4)  # (the watchdog gets the interpreter within 0.5 ms of asking, not Python's 5 ms)
        if deadlines.realtime(deadlines.cycle_threads()[1:], deadlines.DRIVES_PRIORITY):  # the reader (not this
            deadlines.realtime([watchdog], deadlines.DRIVES_PRIORITY + 1)  # idle thread), the watchdog above it
        nodes = ", ".join(str(s.node_id) for s in specs)
        print(f"drives: {args.robot} on {args.interface}:{args.channel}, nodes {nodes}", flush=True)
        _serve(rig, args.duration)
        rig.stop_watching()
        deadlines.unpin(had)
        print(said(rig), file=sys.stderr, flush=True)
    finally:
        network.disconnect()
    return EXIT_OK


def _serve(rig, duration: float | None) -> None:
    """Until ``duration`` [s] or a signal; the collector (held while the cycles run) run only while no drive is
    powered, between runs."""
    done = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    end = None if duration is None else time.monotonic() + duration
    while not done.wait(1.0 if end is None else max(0.0, min(1.0, end - time.monotonic()))):
        if end is not None and time.monotonic() >= end:
            return
        if not gc.isenabled() and not any(d.machine.torque_on for d in rig.drives):
            gc.collect()


def said(rig) -> str:
    """The drives' own figures, in a line: cycles, the largest gap between SYNCs as they arrived, the SYNCs handled
    a cycle or more late, the watchdog's worst wake-up and waits for the reader, what the watchdogs fired for, each
    drive's state, the EMCYs sent."""
    f = rig.figures()
    fired = Counter((code, node) for node, code, _ in f["fired"])
    longest = {code: max(ms for _, c, ms in f["fired"] if c == code) for code, _ in fired}
    why = {0x8100: "SYNC lost", 0x8130: "the host's heartbeat lost"}
    fires = "; ".join(f"0x{code:04X} {why[code]} (none for up to {longest[code]:.1f} ms) on nodes "
                      f"{', '.join(str(n) for c, n in sorted(fired) if c == code)}" for code in sorted(longest))
    faults = [f"{d.node.id}: 0x{c:04X}" for d in rig.drives for c in d.emcy_sent]
    states = ", ".join(f"{d.node.id}: {d.machine.state.name}" for d in rig.drives)
    return (f"drives: {f['cycles']} cycles; SYNC gap max {f['max_sync_gap_ms']:.1f} ms (as received, a drive "
            f"powered); {f['late_syncs']} SYNCs handled a cycle or more late (max {f['max_sync_delay_ms']:.1f} ms); "
            f"watchdog woke up to {f['watchdog_woke_late_ms']:.1f} ms late, waited {f['watchdog_waited']} times for "
            f"unread frames, fired {len(f['fired'])} times" + (f": {fires}" if fires else "") + f"; now {states}"
            + (f"; EMCYs sent {', '.join(faults)}" if faults else ""))


def add_parser(sub) -> None:
    d = sub.add_parser("drives", help="serve simulated CiA 402 drives for a robot on a CAN bus (its MuJoCo model)")
    d.add_argument("robot", help="robot plugin name")
    d.add_argument("--config", default="{}", help="the robot's settings as JSON (as in a scenario's robot section)")
    d.add_argument("--interface", default="udp_multicast", help="python-can interface (udp_multicast: across "
                   "processes on this machine; socketcan, pcan, ...: a real bus)")
    d.add_argument("--channel", default="239.74.163.2", help="its channel (udp_multicast: a multicast group)")
    d.add_argument("--bitrate", type=int, default=1_000_000, help="the bus's bitrate (real interfaces)")
    d.add_argument("--drives", default=None, metavar="JSON", help="the drives as the scenario's backend.drives "
                   "(node ids, units); default: nodes 1.. per joint")
    d.add_argument("--timestep", type=float, default=0.001, help="the plant's step [s] (each cycle runs whole "
                   "steps of it: the host sets the cycle, 0x1006)")
    d.add_argument("--sync-timeout-ms", type=float, default=SYNC_TIMEOUT_MS, help="the drives react (EMCY 0x8100, "
                   "as 0x6007 says: a run sets a quick stop) to no SYNC this long, while powered (default: %(default)g "
                   "= 3 cycles of 250 Hz + 20 ms, the worst stall of a process measured on a 2-core VM, one core "
                   "busy; the host's heartbeat, 60 ms, the other watch)")
    d.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: never)")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=cmd_drives)
