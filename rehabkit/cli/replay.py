"""``rehabkit replay``: a recorded session run again with another controller or planner — a run's folder
(:mod:`rehabkit.rehab.replay`), or a session recorded on a robot as a ROS bag
(:mod:`rehabkit.ros.replay.bag_replay`)."""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK, refuse, unwritable
from rehabkit.cli.run_report import verdict_lines, wrote

BAG_SUFFIXES = (".mcap", ".db3", ".bag")


def _is_bag(path: Path) -> bool:
    return path.suffix in BAG_SUFFIXES or (path / "metadata.yaml").exists()


def cmd_replay(args: argparse.Namespace) -> int:
    fresh = bool(args.out) and not Path(args.out).exists()  # (made by the check below: gone again on a refusal)
    if args.out and (why := unwritable(Path(args.out))) is not None:
        print(why, file=sys.stderr)
        return EXIT_INVALID
    try:
        status = _replay(args)
    except Exception:  # (refused, or failed: nothing half-written left in a folder of its own)
        if fresh:
            shutil.rmtree(args.out, ignore_errors=True)
        raise
    if fresh and status == EXIT_INVALID and not any(Path(args.out).iterdir()):  # (refused before anything ran)
        Path(args.out).rmdir()
    return status


def _replay(args: argparse.Namespace) -> int:
    sets = [*args.set, "ros.bag=true"] if args.bag else args.set
    source = Path(args.source)
    if args.scenario is None and _is_bag(source):
        return refuse(f"error: {source} is a ROS bag: name the scenario to replay it on (--scenario S.yaml: the robot "
                      "it was recorded on, the controller and planner to try)", "bag-needs-scenario", "--scenario")
    if args.scenario is None:
        if args.topics:
            print("error: --topics goes with a bag and --scenario", file=sys.stderr)
            return EXIT_INVALID
        from rehabkit.rehab.replay import replay

        rep = replay(source, sets, args.out, progress=True, fork_at=args.fork_at)
        if rep.result.refusal is None:
            rep.original["deviation"] = _run_deviation(source, rep.result)
    else:
        if args.fork_at is not None:
            print("error: --fork-at goes with a run's folder: a bag holds no simulation state to fork from",
                  file=sys.stderr)
            return EXIT_INVALID
        from rehabkit.ros.replay.bag_replay import replay_bag
        from rehabkit.ros.replay.session_bag import parse_topics

        def say(line: str) -> None:  # (what the replay does without, before it runs)
            print(f"  BAG  {line}", flush=True)

        rep = replay_bag(source, args.scenario, parse_topics(args.topics), sets, args.out, progress=True, say=say)
    if rep.result.refusal is not None:  # the replayed scenario's first plan cannot be made: bad input, said where
        print(str(rep.result.refusal), file=sys.stderr)
        return EXIT_INVALID
    print(rep.table())
    if rep.fork is not None:
        fresh = f"; started afresh: {', '.join(rep.fork['fresh'])}" if rep.fork.get("fresh") else ""
        print(f"  FORK  the recorded session up to {rep.fork['t']:g} s (step {rep.fork['step']}), then the new "
              f"settings{fresh}")
    deviation = rep.original.get("deviation")
    if isinstance(deviation, str):  # (a run's folder without its joints: said why)
        print(f"  DEVIATION  {deviation}")
    elif deviation:
        from rehabkit.ros.replay.deviation import RUN_BAG, said

        whose = "the recorded joints" if args.scenario is not None else f"the run's joints ({source / RUN_BAG})"
        print(f"  DEVIATION  the replay's largest from {whose}: {said(deviation)}")
    for line in verdict_lines(rep.result.summary):  # (why it exits as it does, as a run says it)
        print(line)
    print(wrote(rep.result.summary, rep.result.out_dir))
    return EXIT_OK if rep.result.passed else EXIT_FAILED


def _run_deviation(run_dir: Path, result) -> list[dict] | str:
    """The replay's largest deviation from the joints of the run it replays (its bag, where the run wrote one), or
    why it is not known."""
    from rehabkit.ros.replay.bag_content import BagError
    from rehabkit.ros.replay.deviation import RUN_BAG, run_deviation

    if not (run_dir / RUN_BAG).exists():
        return f"not known: {run_dir} holds no {RUN_BAG} (the run's joints are kept with rehabkit run --bag)"
    try:
        return run_deviation(run_dir, result.trace, result.summary.get("per_joint", {})) or []
    except BagError as exc:
        return f"not known: {exc}"


def add_parser(sub) -> None:
    rp = sub.add_parser("replay", help="run a recorded session again with other settings (same seed, targets, "
                                       "patient), or a session's ROS bag on a scenario; prints the outcome measures "
                                       "side by side")
    rp.add_argument("source", metavar="RUN_DIR|BAG", help="a folder written by 'rehabkit run', or a ROS bag recorded "
                                                          "on a robot (a rosbag2 folder, .mcap, .db3 or ROS 1 .bag)")
    rp.add_argument("--scenario", metavar="S.yaml", help="a bag's replay: the scenario to run it on")
    rp.add_argument("--topics", action="append", default=[], metavar="ROLE=TOPIC,...",
                    help="a bag's topics where not /joint_states, /wrench, /targets, /reference/joint_states (the "
                         "targets also read from TOPIC/pose and TOPIC/joint_states where the bag has them; e.g. "
                         "joint_states=/arm/joint_states,wrench=/cuff/wrench; ROLE= for none)")
    rp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="what to change, e.g. controller.type=assist-as-needed")
    rp.add_argument("--out", metavar="DIR", help="output folder (default: RUN_DIR/replay-<values>, or "
                                                 "<BAG>-replay-<values> beside the bag)")
    rp.add_argument("--bag", action="store_true", help="also write run.mcap, a ROS 2 bag of the replay")
    rp.add_argument("--fork-at", type=float, metavar="T", help="keep the recorded session up to T seconds and go on "
                    "from there with the new settings (same person, same state); a run's folder only")
    rp.set_defaults(func=cmd_replay)
