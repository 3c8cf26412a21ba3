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


class ClearRefusedError(PermissionError):
    """The bridge at ``bridge`` refused a clear: ``reason`` (key-needed: it has a key and this end none; no-right: the
    session may not clear, as the bridge declares), ``words``."""

    def __init__(self, bridge: str, reason: str, words: str):
        self.bridge, self.reason, self.words = bridge, reason, words
        super().__init__(f"the bridge at {bridge} refuses: {words}")


def clear_over_link(host: str, port: int, robot_id: int, by: str, key_file: str | None = None,
                    timeout: float = 2.0) -> int:
    """Tell the bridge ``by`` (a person's name) clears its e-stop, in an authenticated session given the robot's
    key; wait for a state saying it is no longer latched. Its status (``CLEARED`` set where a latched e-stop was
    cleared, unset where nothing was latched); :class:`ClearRefusedError` if the bridge refuses."""
    from rehabkit.hardware.link.clock import wait_readable
    from rehabkit.hardware.link.protocol import (
        CLEAR,
        CLEAR_AT_KEYPAD,
        ESTOPPED,
        HEADER,
        NO_RIGHT,
        PLAIN,
        STATE,
        pack_bytes,
    )
    from rehabkit.hardware.security.handshake import BYE, KEY_NEEDED, handshake, peek_kind, refusal_words, refused
    from rehabkit.hardware.security.keys import load_key

    key = load_key(key_file) if key_file else None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    seq = iter(range(1, 1 << 31))
    bridge = (socket.gethostbyname(host), port)  # (as its datagrams say where they came from)
    link = PLAIN
    try:
        link = handshake(sock, bridge, key, robot_id, lambda: next(seq), timeout) if key else PLAIN
        until = time.monotonic() + timeout
        # (the name padded to 16 bytes at least: the bridge's refusal is never bigger than what it answers)
        name = by.encode().ljust(16)
        while time.monotonic() < until:
            sock.sendto(link.seal(pack_bytes(CLEAR, robot_id, next(seq), name, link.id)), bridge)
            answer_by = time.monotonic() + 0.05
            while wait_readable(sock, answer_by - time.monotonic()):
                try:
                    data, came_from = sock.recvfrom(65536)
                except (BlockingIOError, ConnectionRefusedError):
                    break
                if came_from != bridge:
                    continue
                if peek_kind(data) != STATE:
                    if key is None and (got := refused(data, robot_id)) is not None and got[0] == KEY_NEEDED:
                        raise ClearRefusedError(f"udp://{host}:{port}", "key-needed",
                                                f"{refusal_words(KEY_NEEDED, None)}; clear it with the key it takes "
                                                "clears under: --key FILE, the bridge's clearing key if it was started "
                                                "with --clear-key, else the robot's key (or at its keypad)")
                    continue
                plain, _ = link.open(data)
                status = HEADER.unpack_from(plain)[9] if plain is not None else ESTOPPED
                if status & NO_RIGHT:
                    raise ClearRefusedError(f"udp://{host}:{port}", "no-right", "the bridge takes a clear only at its "
                                            "keypad (--clear-with keypad)" if status & CLEAR_AT_KEYPAD else
                                            "the bridge takes a clear only in a session under its clearing key: "
                                            "--key its --clear-key file (not the robot's key), or at its keypad")
                if not status & ESTOPPED:
                    return status
        raise TimeoutError(f"no state from the bridge at udp://{host}:{port} saying it is cleared within {timeout:g} s")
    finally:
        if link is not PLAIN:  # (the session ends: a host's run may begin at once)
            sock.sendto(link.seal(pack_bytes(BYE, robot_id, next(seq), b"", link.id)), bridge)
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
    e.add_argument("--key", metavar="FILE", help="with --bridge: the link key a bridge with a key takes clears "
                   "under, in an authenticated session: the robot's key, or, if the bridge was started with "
                   "--clear-key, that clearing key (the robot's key does not clear there)")
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
