"""``rehabkit audit RUN_DIR``: check a run's safety log (its hash chain) and print it.

A run killed on the way (SIGKILL, the power gone) leaves a log written up to its last record: the chain is checked
that far and the log said to end without its closing record; a last line cut short as it was written is left out,
said so. Exit 0 when the chain holds, 1 when it does not (tampered), 2 without a log."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rehabkit.cli.exits import EXIT_FAILED, EXIT_INVALID, EXIT_OK
from rehabkit.core.log.safety_log import KEY_ENV, LOG, audit_key, check


def _link(link: dict | None) -> str:
    """A robot link's record: the bridge, and the session's key id (or that it had none)."""
    if not link:
        return ""
    return f"  link {link.get('bridge')}: " + (f"session {link['session']}, key {link['key_id']}" if "key_id" in link
                                               else str(link.get("session")))


def _line(record: dict) -> str:
    kind = record.get("kind")
    if kind == "run":
        s = record.get("scenario", {})
        return (f"run      {record.get('time')}  rehabkit {record.get('software', {}).get('rehabkit')}  "
                f"{s.get('file')} (sha256 {str(s.get('sha256'))[:12]}…)  patient {record.get('patient')}  "
                f"backend {record.get('backend')}  seed {record.get('seed')}" + _link(record.get("link")))
    if kind == "limits":
        narrowed = {j: list(v["narrowed_by"]) for j, v in record.get("joints", {}).items() if v.get("narrowed_by")}
        return (f"limits   {len(record.get('joints', {}))} joints, narrowed: {narrowed or 'none'}; interaction force "
                f"{record.get('interaction_force_n')} N; keep-in {'yes' if record.get('keep_in') else 'no'}; "
                f"stop: {record.get('stop')}")
    if kind == "intervention":
        return f"event    {record.get('message')}"
    if kind == "end":
        return (f"end      passed {record.get('passed')}, safety events {record.get('safety_events')}, "
                f"{record.get('sim_time_s')} s simulated")
    return f"{kind}"


def cmd_audit(args: argparse.Namespace) -> int:
    path = Path(args.run_dir) / LOG
    if not path.exists():
        print(f"{args.run_dir}: no {LOG} (a run writes one with --out)", file=sys.stderr)
        return EXIT_INVALID
    log = check(path, audit_key())
    records = log.records
    for record in records:
        print(f"{record.get('seq', '?'):>3}  {_line(record)}")
    if log.torn is not None:
        print(f"torn     the last line is cut short ({log.torn!r}…): a write the process's end interrupted; "
              "left out")
    if records and not log.finished:
        last = records[-1]
        at = f" (t={last['t']:g} s)" if isinstance(last.get("t"), (int, float)) else ""
        print(f"unfinished  the log ends without its closing record: the run did not finish (killed, or the machine "
              f"stopped); checked up to its last record, {last.get('seq', '?')} ({last.get('kind')}{at})")
    if log.problems:
        for problem in log.problems:
            print(f"TAMPERED: {problem}", file=sys.stderr)
        return EXIT_FAILED
    keyed = f", keyed ({KEY_ENV})" if audit_key() is not None else ""
    print(f"chain intact: {len(records)} records{keyed}{'' if log.finished else ' (up to where it ends)'}; "
          f"last hash {records[-1]['hash']}")
    return EXIT_OK


def add_parser(sub) -> None:
    a = sub.add_parser("audit", help="check a run's safety log (hash chain) and print it")
    a.add_argument("run_dir", help="the run's folder (rehabkit run --out DIR)")
    a.set_defaults(func=cmd_audit)
