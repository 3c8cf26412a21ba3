"""``rehabkit bridge``: serve a robot over UDP next to its drives (here: its MuJoCo model as the plant, with the run's
instruments and a test rig's loads), and keep its e-stop latch."""

from __future__ import annotations

import argparse
import json
import signal
import sys

from rehabkit.cli.exits import EXIT_INTERRUPTED, EXIT_INVALID, EXIT_OK, Refusal, refuse


def _err(msg: str) -> None:
    print(msg, file=sys.stderr)


def cmd_bridge(args: argparse.Namespace) -> int:
    import numpy as np

    from rehabkit.core.kinds.sensor import Instrument
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.safety.estop import EStopLatch
    from rehabkit.core.scenario.loads import Load
    from rehabkit.hardware.bridge import Bridge
    from rehabkit.hardware.bridge_limits import BridgeLimits
    from rehabkit.hardware.plant import MujocoPlant

    registry = default_registry()
    info = registry.get("robot", args.robot)
    from pathlib import Path

    from rehabkit.core.kinds.context import Context

    # a robot's files (a URDF, meshes) relative to where the bridge runs (a host spawning it: the scenario's folder)
    here = Context(Path.cwd(), np.random.default_rng(args.seed), 1.0 / args.rate)
    robot = info.factory(info.config.model_validate({**json.loads(args.config), "type": args.robot}), here)
    where = _listen(args, f"{robot.model.name}-{args.robot_id}")
    if isinstance(where, Refusal):
        return refuse(f"error: {where.message}", where.code, where.option)
    host, port, key = where
    clear_key = None
    if key is not None:
        from rehabkit.hardware.security.keys import KeyFileError, check_robot, load_key

        for flag in ("--key", "--clear-key"):
            try:
                if flag == "--key":
                    check_robot(key, f"{robot.model.name}-{args.robot_id}")
                elif args.clear_key:  # the right to clear an e-stop: a second key, not the one that drives
                    clear_key = load_key(args.clear_key)
                    check_robot(clear_key, f"{robot.model.name}-{args.robot_id}")
            except KeyFileError as exc:
                _err(f"error: {flag}: {exc}")
                return EXIT_INVALID
        if clear_key is not None and clear_key.id == key.id:
            _err("error: --clear-key is the robot's own key: the right to clear is a second key (`rehabkit keys new "
                 f"{key.robot} --out FILE`)")
            return EXIT_INVALID
    elif args.clear_key:
        _err("error: --clear-key needs --key (a bridge without a key clears over loopback, or at its keypad)")
        return EXIT_INVALID
    try:
        instruments = [Instrument(**{**i, "position": tuple(i["position"]), "bias": tuple(i.get("bias", (0, 0, 0)))})
                       for i in json.loads(args.instruments or "[]")]
        loads = [Load.model_validate(x) for x in json.loads(args.loads or "[]")]
        plant = MujocoPlant(robot, 1.0 / args.rate, instruments, loads, seed=args.seed)
    except (ValueError, TypeError, KeyError) as exc:
        _err(f"error: --instruments/--loads: {exc}")
        return EXIT_INVALID
    if args.effort is not None:
        effort = np.asarray(json.loads(args.effort), float)
        if effort.shape != plant.effort.shape or np.any(effort <= 0):
            _err(f"error: --effort needs {len(plant.effort)} positive torques [N·m], got {args.effort}")
            return EXIT_INVALID
        plant.effort = np.minimum(plant.effort, effort)  # never above the robot's own
    limits = robot.model.limits  # the robot's own, unless the host sends the run's (narrowed by patient, envelope)
    lower, upper, velocity = limits.lower, limits.upper, limits.velocity
    if args.limits is not None:
        try:
            given = json.loads(args.limits)
            lower, upper, velocity = (np.asarray(given[k], float) for k in ("lower", "upper", "velocity"))
            if not lower.shape == upper.shape == velocity.shape == (plant.joints,):
                raise ValueError(f"each needs {plant.joints} values")
        except (ValueError, KeyError, TypeError) as exc:
            _err(f"error: --limits needs lower, upper and velocity per joint: {exc}")
            return EXIT_INVALID
    backstop = BridgeLimits(lower, upper, velocity, margin=np.radians(args.limit_margin_deg),
                            margin_m=args.limit_margin_m, revolute=robot.model.revolute)
    from rehabkit.hardware.config import HardwareConfig  # its defaults are the host's: a bridge by hand agrees

    defaults = HardwareConfig.model_fields
    watchdog_ms = defaults["bridge_watchdog_ms"].default if args.watchdog_ms is None else args.watchdog_ms
    stale_ms = defaults["bridge_stale_ms"].default if args.stale_ms is None else args.stale_ms
    latch = EStopLatch.for_robot(robot.model.name, args.robot_id, args.latch_file)  # (as the host names it)
    from rehabkit.core.safety.estop import state_dir
    from rehabkit.hardware.keypad import Keypad
    from rehabkit.hardware.security.events import SecurityLog

    name = f"{robot.model.name}-{args.robot_id}"
    log = SecurityLog(args.security_log or state_dir() / "security" / f"{name}.jsonl")
    bridge = Bridge(plant, args.robot_id, port, host=host, watchdog_s=watchdog_ms / 1e3, stale_s=stale_ms / 1e3,
                    limits=backstop, latch=latch, keypad=Keypad() if args.keypad else None, key=key,
                    clear_key=clear_key, clear_right=args.clear_with, log=log)
    print(f"bridge: {args.robot} on udp://{host}:{bridge.port}", flush=True)
    if key is not None:
        print(f"bridge: authenticated sessions only, {key}", file=sys.stderr, flush=True)
    print(f"bridge: refused attempts go to {log.path}", file=sys.stderr, flush=True)
    clears = {"key": f"only in a session under its clearing key (--clear-key: key {clear_key.id})"
              if clear_key is not None else "",
              "keypad": "only at its keypad (--clear-with keypad)" + ("" if args.keypad else ": give it --keypad"),
              "link": "in any session" + (" under its key" if key is not None else "")}[bridge.clear_right]
    print(f"bridge: a latched e-stop is cleared {clears}", file=sys.stderr, flush=True)
    print("bridge: keypad on standard input: e presses the e-stop, c clears it, a lets a new host take the session "
          "over" if args.keypad else "bridge: no keypad (--keypad reads one from standard input)", file=sys.stderr,
          flush=True)
    from threadpoolctl import threadpool_limits

    from rehabkit.hardware.bridge_clocks import serve, serve_lockstep

    # stopped by SIGINT or SIGTERM alike, its --stats written either way (a bridge started with & in a script has
    # SIGINT ignored unless it says otherwise)
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    # SIGHUP: the key file read again (rotated: the sessions under the old key end), at the loop's next turn
    signal.signal(signal.SIGHUP, lambda *_: setattr(bridge, "reload", True))
    stopped_by = None
    try:
        with threadpool_limits(limits=1, user_api="blas"):  # small matrices: BLAS workers would only spin
            (serve_lockstep if args.lockstep else serve)(bridge, args.duration, parent=args.parent_pid)
    except KeyboardInterrupt as exc:
        stopped_by = getattr(exc, "signal", None) or "SIGINT"
    finally:
        if args.stats:
            from rehabkit.core.io import atomic_write_json

            atomic_write_json(args.stats, bridge.link_stats())
    if stopped_by is None:
        return EXIT_OK
    # (not main's "nothing was written": the bridge wrote its --stats and its security log)
    print(f"bridge: stopped by {stopped_by}; wrote " + (f"--stats {args.stats}, " if args.stats else "")
          + f"the security log {log.path} ({log.written} lines)", file=sys.stderr, flush=True)
    return 143 if stopped_by == "SIGTERM" else EXIT_INTERRUPTED


def _interrupt(signum, frame) -> None:
    exc = KeyboardInterrupt()
    exc.signal = signal.Signals(signum).name
    raise exc


def _listen(args: argparse.Namespace, name: str) -> tuple[str, int, object] | Refusal:
    """Where the bridge for robot ``name`` (``hit-1``) listens and its key, or why it must not start (its words, the
    code and the option refused): beyond loopback only with a key."""
    import ipaddress

    from rehabkit.hardware.security.keys import KeyFileError, load_key

    host, port = "127.0.0.1", args.port
    if args.listen:
        host, _, given = args.listen.rpartition(":")
        if not host or not given.isdigit():
            return Refusal("listen-format", "--listen",
                           f"--listen takes HOST:PORT (e.g. 0.0.0.0:7000 or 192.168.1.20:7000), not '{args.listen}'")
        host, port = host.strip("[]"), int(given)
    key = None
    if args.key:
        try:
            key = load_key(args.key)
        except KeyFileError as exc:
            return Refusal("key-file", "--key", f"--key: {exc}")
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = host == "localhost"
    if not loopback and key is None:
        return Refusal("listen-needs-key", "--listen",
                       f"--listen {args.listen}: beyond this machine's loopback anyone on the network could drive the "
                       f"robot; give the bridge the robot's key (`rehabkit keys new {name}`, then --key FILE, "
                       "the same file as the host's backend.key_file)")
    return host, port, key


def add_parser(sub) -> None:
    b = sub.add_parser("bridge", help="serve a robot over UDP (its MuJoCo model as the plant), next to its drives")
    b.add_argument("robot", help="robot plugin name")
    b.add_argument("--port", type=int, default=0, help="UDP port on loopback (0: any free one; printed)")
    b.add_argument("--listen", metavar="HOST:PORT", help="listen there instead (beyond loopback only with --key)")
    b.add_argument("--key", metavar="FILE", help="the robot's link key (`rehabkit keys new ROBOT-ID`): serve "
                   "authenticated sessions only")
    b.add_argument("--clear-key", metavar="FILE", help="a second key, for clearing a latched e-stop over the link: "
                   "then only a session under it clears (and does nothing else); one under --key does not")
    b.add_argument("--clear-with", choices=["link", "keypad"], default="link", help="who may clear a latched e-stop: "
                   "link (default: a session, under --clear-key if given), keypad (the keypad at the robot only)")
    b.add_argument("--security-log", metavar="FILE", help="where refused attempts are written as they happen, a JSON "
                   "line each, at most 10 a second (default: $REHABKIT_STATE/security/ROBOT-ID.jsonl)")
    b.add_argument("--stats", metavar="FILE", help="at exit, write what the link accepted and dropped (by reason) and "
                   "its sessions (key ids) as JSON")
    b.add_argument("--config", default="{}", help="the robot's settings as JSON (as in a scenario's robot section; "
                   "its files relative to the folder the bridge runs in)")
    b.add_argument("--rate", type=float, default=1000.0, help="plant and link rate [Hz]")
    b.add_argument("--robot-id", type=int, default=1, help="the robot's id on the link (the scenario's "
                   "backend.robot_id); with the robot model's name it names the robot's key and e-stop latch: "
                   "ROBOT-ID, e.g. hit-1")
    b.add_argument("--watchdog-ms", type=float, default=None,
                   help="hold the robot without valid commands this long (default: the host backend's, 50 ms)")
    b.add_argument("--stale-ms", type=float, default=None,
                   help="hold the posture after this long without a newer command, until the next one")
    b.add_argument("--limits", default=None, metavar="JSON",
                   help="the run's joint limits {lower, upper, velocity} (default: the robot's); beyond them by the "
                        "margin, or 25%% too fast, the bridge holds the robot on its own")
    # (the defaults are bridge_limits.MARGIN_DEG and MARGIN_M, not imported here: numpy would come with them)
    b.add_argument("--limit-margin-deg", type=float, default=2.0,
                   help="how far beyond a revolute joint's range the bridge's own check trips (the host's trips at "
                        "0.5°)")
    b.add_argument("--limit-margin-m", type=float, default=0.01,
                   help="how far beyond a prismatic joint's range the bridge's own check trips, in metres (the "
                        "host's trips at 5 mm)")
    b.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: never)")
    b.add_argument("--lockstep", action="store_true",
                   help="tick once per host tick, on the host's clock (backend.clock: lockstep), not the wall's")
    b.add_argument("--parent-pid", type=int, default=None, help="stop when this process (the host) is gone")
    b.add_argument("--effort", default=None, metavar="JSON",
                   help="torque limits per joint [N·m], tighter than the robot's (a safety envelope's)")
    b.add_argument("--instruments", default=None, metavar="JSON",
                   help="the run's instruments (force-torque sensors, accelerometers) the plant reads and each "
                        "state carries, in the host's order")
    b.add_argument("--loads", default=None, metavar="JSON", help="a test rig's loads on the plant (world.loads)")
    b.add_argument("--seed", type=int, default=0, help="seed of the simulated instruments' noise")
    b.add_argument("--latch-file", default=None, metavar="PATH",
                   help="where the e-stop latch is kept across bridge restarts (default: under $REHABKIT_STATE, "
                        "per robot and robot id)")
    b.add_argument("--keypad", action="store_true",
                   help="read keys at the robot from standard input, a line each: e presses the e-stop, c clears it, a "
                        "lets a new host take a live session over (for 30 s); read whatever the clock (lock-step too)")
    b.set_defaults(func=cmd_bridge)
