"""``rehabkit assess``: measure the active and passive range of motion of the person in a scenario
(:mod:`rehabkit.rehab.assess`) and write the next version of their profile."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK


def cmd_assess(args: argparse.Namespace) -> int:
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.source import parse_override
    from rehabkit.core.setup.errors import SetupError
    from rehabkit.rehab.assess import assess

    out = Path(args.out or f"out/{Path(args.scenario).stem}_assessment")
    try:
        result = assess(args.scenario, out, args.set, joints=args.joints.split(",") if args.joints else None,
                        damping=args.damping, stretch_settings={".".join(key): value for key, value in
                                                                 map(parse_override, args.stretch)})
    except ScenarioError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_INVALID
    except ValueError as exc:  # a --set or --stretch that is not key=value, a --joints the robot cannot assess
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except SetupError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    print(f"{'joint':<16} {'active [deg]':>16} {'passive [deg]':>16}  passive ends by")
    for name, ends in result.passive.items():
        act = result.active[name]
        a = f"{act[0]:7.1f} .. {act[1]:6.1f}" if act is not None else f"{'stopped':>17}"
        p = " .. ".join(f"{e:6.1f}" if e is not None else "     –" for e in ends)
        print(f"{name:<16} {a} {p:>17}  {' / '.join(w or '–' for w in result.stopped_by[name])}")
    for which, run in result.runs.items():
        if run.summary["safety"]["events"]:
            print(f"the {which} session was stopped: {run.summary['safety']['events'][0]['message']}")
        if steps := run.summary["metrics"].get("contact_steps"):
            print(f"the {which} session's robot touched the scene ({steps} control steps): its ranges are the "
                  "scene's, not the person's, and not kept (clear the workspace, or leave the objects out with "
                  "--set world.objects=[])")
    print(f"wrote {result.profile_file} (next session: --set patient={result.profile_file}) and "
          f"{out / 'assessment.json'}")
    return EXIT_OK if result.complete else EXIT_FAILED


def add_parser(sub) -> None:
    a = sub.add_parser("assess", help="measure a person's active and passive range of motion; write the next "
                                      "version of their profile")
    a.add_argument("scenario", help="a scenario with the robot, backend and patient (its task is not used)")
    a.add_argument("--out", metavar="DIR", help="output folder (default: out/<scenario>_assessment)")
    a.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a.add_argument("--joints", metavar="A,B", help="joints to assess (default: the profile's)")
    a.add_argument("--stretch", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the passive stretch (see `rehabkit plugins --fields passive-stretch`)")
    a.add_argument("--damping", type=float, default=0.0, metavar="NMS_RAD",
                   help="viscous damping the transparent robot keeps (a person who would move it too fast)")
    a.set_defaults(func=cmd_assess)
