"""``rehabkit estop``: list the e-stop latches kept on this machine, or clear one — a person's deliberate act, recorded
with their name. ``NAME`` is the latch's (``hit-1``: robot ``hit`` with robot id 1 behind a bridge; ``sim-hit``: the
simulated HIT). With ``--bridge HOST:PORT`` the running bridge is told to clear its own latch."""

from __future__ import annotations

import argparse
import socket
import sys
import time

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK
from rehabkit.core.safety.estop import EStopLatch, all_latches


def clear_over_link(host: str, port: int, robot: str, robot_id: int, timeout: float = 2.0) -> int:
    """Send the bridge a clear command and wait for a state saying its e-stop is no longer latched; the status."""
    import numpy as np

    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.hardware.protocol import CMD_CLEAR, COMMAND, ESTOPPED, encode

    info = default_registry().get("robot", robot)
    dof = info.factory(info.config.model_validate({"type": robot}), None).model.dof
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(0.05)
    try:
        until = time.monotonic() + timeout
        while time.monotonic() < until:
            sock.sendto(encode(COMMAND, robot_id, 1, np.zeros(dof), status=CMD_CLEAR), (host, port))
            try:
                data = sock.recv(65536)
            except (TimeoutError, ConnectionRefusedError):
                continue
            status = _status(data, robot_id)
            if status is not None and not status & ESTOPPED:
                return status
        raise TimeoutError(f"no state from the bridge at udp://{host}:{port} saying it is cleared within {timeout:g} s")
    finally:
        sock.close()


def _status(data: bytes, robot_id: int) -> int | None:
    from rehabkit.hardware.protocol import CRC, HEADER, MAGIC, STATE, VERSION

    if len(data) < HEADER.size + CRC.size:
        return None
    magic, version, kind, rid, *_rest = HEADER.unpack_from(data)
    ok = magic == MAGIC and version == VERSION and kind == STATE and rid == robot_id
    return HEADER.unpack_from(data)[9] if ok else None


def cmd_estop(args: argparse.Namespace) -> int:
    if args.action == "list":
        latches = all_latches()
        for latch in latches:
            print(latch.describe())
        if not latches:
            print("no e-stop latch on this machine")
        return EXIT_OK
    if not args.name or not args.by:
        print("error: clearing an e-stop is a person's act, recorded with their name: `rehabkit estop clear NAME --by "
              "WHO` (NAME from `rehabkit estop list`)", file=sys.stderr)
        return EXIT_INVALID
    if args.bridge:
        robot, _, rid = args.name.rpartition("-")
        host, _, port = args.bridge.rpartition(":")
        if not robot or not rid.isdigit() or not port.isdigit():
            print("error: --bridge HOST:PORT clears NAME = ROBOT-ID (e.g. hit-1)", file=sys.stderr)
            return EXIT_INVALID
        try:
            clear_over_link(host or "127.0.0.1", int(port), robot, int(rid))
        except (TimeoutError, OSError, KeyError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_FAILED
        print(f"{args.name}: cleared at the bridge udp://{args.bridge} (by {args.by}); the next session ramps in")
        return EXIT_OK
    latch = EStopLatch.named(args.name)
    if not latch.path.exists():  # (a misspelt name must not pass for a cleared e-stop)
        from rehabkit.core.plugins.names import suggest

        known = [x.name for x in all_latches()]
        print(f"error: no e-stop latch named '{args.name}' on this machine{suggest(args.name, known)} (latches: "
              f"{', '.join(known) or 'none'}; `rehabkit estop list`)", file=sys.stderr)
        return EXIT_INVALID
    was = latch.clear(args.by)
    if was is None:
        print(f"{args.name}: not latched")
        return EXIT_OK
    print(f"{args.name}: cleared by {args.by} (latched since {was['since']}: {was['reason']}); the next session "
          "ramps in")
    return EXIT_OK


def add_parser(sub) -> None:
    e = sub.add_parser("estop", help="list the e-stop latches, or clear one (a person's deliberate act)")
    e.add_argument("action", choices=["list", "clear"])
    e.add_argument("name", nargs="?", help="the latch: ROBOT-ID behind a bridge (hit-1), sim-ROBOT in simulation")
    e.add_argument("--by", help="who clears it (kept in the latch's record)")
    e.add_argument("--bridge", metavar="HOST:PORT", help="tell this running bridge to clear its latch")
    e.set_defaults(func=cmd_estop)
