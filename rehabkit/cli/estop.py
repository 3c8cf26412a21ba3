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


def clear_over_link(host: str, port: int, robot_id: int, by: str, key_file: str | None = None,
                    timeout: float = 2.0) -> int:
    """Tell the bridge ``by`` (a person's name) clears its e-stop, in an authenticated session given the robot's
    key; wait for a state saying it is no longer latched. Its status (``CLEARED`` set where a latched e-stop was
    cleared, unset where nothing was latched)."""
    from rehabkit.hardware.link.clock import wait_readable
    from rehabkit.hardware.link.protocol import CLEAR, ESTOPPED, HEADER, PLAIN, STATE, pack_bytes
    from rehabkit.hardware.security.handshake import handshake, peek_kind, refusal
    from rehabkit.hardware.security.keys import load_key

    key = load_key(key_file) if key_file else None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    seq = iter(range(1, 1 << 31))
    try:
        link = handshake(sock, (host, port), key, robot_id, lambda: next(seq), timeout) if key else PLAIN
        until = time.monotonic() + timeout
        while time.monotonic() < until:
            sock.sendto(link.seal(pack_bytes(CLEAR, robot_id, next(seq), by.encode(), link.id)), (host, port))
            answer_by = time.monotonic() + 0.05
            while wait_readable(sock, answer_by - time.monotonic()):
                try:
                    data = sock.recv(65536)
                except (BlockingIOError, ConnectionRefusedError):
                    break
                if peek_kind(data) != STATE:
                    if (why := refusal(data, robot_id, key)) is not None:
                        raise PermissionError(f"the bridge at udp://{host}:{port} refuses: {why}; clear it with the "
                                              "robot's key: --key FILE")
                    continue
                plain, _ = link.open(data)
                if plain is not None and not HEADER.unpack_from(plain)[9] & ESTOPPED:
                    return HEADER.unpack_from(plain)[9]
        raise TimeoutError(f"no state from the bridge at udp://{host}:{port} saying it is cleared within {timeout:g} s")
    finally:
        sock.close()


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
        from rehabkit.hardware.security.handshake import LinkRefusedError
        from rehabkit.hardware.security.keys import KeyFileError

        try:
            if args.key:  # (a key is one robot's: NAME must be that robot)
                from rehabkit.hardware.security.keys import check_robot, load_key

                check_robot(load_key(args.key), args.name)
            status = clear_over_link(host or "127.0.0.1", int(port), int(rid), args.by, args.key)
        except (KeyFileError, LinkRefusedError, PermissionError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_INVALID
        except (TimeoutError, OSError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_FAILED
        from rehabkit.hardware.link.protocol import CLEARED

        if not status & CLEARED:  # (the bridge says whether a latched e-stop was cleared)
            print(f"{args.name}: not latched at the bridge udp://{args.bridge}")
            return EXIT_OK
        print(f"{args.name}: cleared at the bridge udp://{args.bridge} (by {args.by}); the next session ramps in")
        return EXIT_OK
    latch = EStopLatch.named(args.name)
    if not latch.path.exists():  # (a misspelt name must not pass for a cleared e-stop)
        from rehabkit.core.kinds.names import suggest

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
    e.add_argument("--key", metavar="FILE", help="the robot's link key: a bridge with a key clears only in an "
                   "authenticated session")
    e.set_defaults(func=cmd_estop)


def latched_note(setup) -> str:
    """``validate``'s line for a robot whose e-stop latch on this machine (where its backend keeps one) is latched:
    a run is refused until a person clears it."""
    sc = setup.sc
    template = setup.registry.get("backend", sc.backend.type).declared.latch_name
    if template is None:
        return ""
    name = template.format(robot=setup.robot.model.name, **sc.backend.model_dump())
    if EStopLatch.named(name).latched() is None:
        return ""
    return (f"\n  LATCHED the robot's e-stop ({name}) is latched: a run is refused until a person clears it "
            f"(`rehabkit estop clear {name} --by NAME`)")
