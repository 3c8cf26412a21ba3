"""``rehabkit safety-report``: the safety skills in simulation, over the link and on CANopen drives, a table per
skill."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK


def cmd_safety_report(args: argparse.Namespace) -> int:
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.safety_report.render import write_report
    from rehabkit.safety_report.report import skill_runs

    paths = [Path(p) for p in args.scenarios] or sorted(Path("scenarios/safety").glob("*.yaml"))
    if not paths:
        print("error: no safety-skill scenarios given (and none in scenarios/safety/)", file=sys.stderr)
        return EXIT_INVALID
    try:
        backends = tuple(args.backends.split(","))
        runs = skill_runs(paths, args.reactions.split(",") if args.reactions else None, backends)
    except ScenarioError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_INVALID
    md, html = write_report(runs, Path(args.out), backends)
    print(md.read_text())
    print(f"wrote {md} and {html}")
    return EXIT_OK if all(r.passed for row in runs for r in row if r is not None) else EXIT_FAILED


def _reactions(text: str) -> str:
    wrong = [r for r in text.split(",") if r not in ("stop", "yield", "retreat")]
    if wrong:
        raise argparse.ArgumentTypeError(f"{', '.join(wrong)}: a reaction is stop, yield or retreat")
    return text


def _backends(text: str) -> str:
    wrong = [b for b in text.split(",") if b not in ("simulation", "link", "canopen")]
    if wrong:
        raise argparse.ArgumentTypeError(f"{', '.join(wrong)}: a backend is simulation, link or canopen")
    return text


def add_parser(sub) -> None:
    r = sub.add_parser("safety-report", help="run safety-skill scenarios in simulation, over the link and on "
                                             "CANopen drives; a report per skill (Markdown and HTML with plots)")
    r.add_argument("scenarios", nargs="*", help="skill scenarios (default: scenarios/safety/*.yaml)")
    r.add_argument("--out", default="out/safety_report", metavar="DIR")
    r.add_argument("--reactions", metavar="LIST", type=_reactions, help="run each skill with an interaction-force "
                   "limit once per reaction, side by side, e.g. stop,yield,retreat (default: as its scenario says)")
    r.add_argument("--backends", metavar="LIST", type=_backends, default="simulation,link,canopen",
                   help="the columns: simulation, link (UDP to a bridge), canopen (simulated CiA 402 drives)")
    r.set_defaults(func=cmd_safety_report)
