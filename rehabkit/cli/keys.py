"""``rehabkit keys``: make a robot's link key (``new``), or say what a key file holds without its secret (``show``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rehabkit.cli.exits import EXIT_INVALID, EXIT_OK


def cmd_keys(args: argparse.Namespace) -> int:
    from rehabkit.hardware.security.keys import KeyFileError, default_key_path, load_key, new_key

    try:
        if args.action == "new":
            out = args.out or default_key_path(args.robot)
            key = new_key(args.robot, out, replace=args.replace)
            print(f"{key.robot}: key {key.id} written to {out} (owner-only). Give the same file to the bridge "
                  f"(`rehabkit bridge ... --key {out}`) and to the host (backend.key_file); copy it over a channel "
                  "you trust (scp, a USB stick), never by e-mail or chat")
            tree = unignored_in_git(Path(out))
            if tree is not None:
                print(f"warning: {out} is inside the git work tree {tree} and git does not ignore it: a commit could "
                      f"publish the secret. Add it to {tree / '.gitignore'} (e.g. a line `*.key`), or keep keys "
                      "outside the tree (the default place: $REHABKIT_STATE/keys/)", file=sys.stderr)
        else:
            key = load_key(args.robot)
            print(f"{key.path}: key {key.id} for {key.robot}")
    except KeyFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    return EXIT_OK


def unignored_in_git(path: Path) -> Path | None:
    """The git work tree ``path`` lies in where git would not ignore it (None: no tree, ignored, or no git)."""
    import shutil
    import subprocess

    if shutil.which("git") is None:
        return None
    folder = path.resolve().parent
    top = subprocess.run(["git", "-C", str(folder), "rev-parse", "--show-toplevel"], capture_output=True, text=True)
    if top.returncode:
        return None
    ignored = subprocess.run(["git", "-C", str(folder), "check-ignore", "-q", str(path.resolve())])
    return None if ignored.returncode == 0 else Path(top.stdout.strip())


def add_parser(sub) -> None:
    k = sub.add_parser("keys", help="make a robot's link key (the same file at the host and at the bridge)")
    k.add_argument("action", choices=["new", "show"], help="new ROBOT-ID: a fresh key; show FILE: its robot and id")
    k.add_argument("robot", metavar="ROBOT-ID|FILE", help="new: the robot as its e-stop latch is named: its model's "
                   "name and its robot_id (hit-1; a URDF's <robot name>, an MJCF's model); show: the key file")
    k.add_argument("--out", metavar="FILE", help="where to write it (default: $REHABKIT_STATE/keys/ROBOT-ID.key)")
    k.add_argument("--replace", action="store_true", help="write over an existing key file (rotating the key)")
    k.set_defaults(func=cmd_keys)
