"""``rehabkit`` command line: run, sweep, replay, validate, plugins, schema, bridge, drives, audit, estop, assess,
safety-report, export, progress.

Exit codes: 0 success (all expectations met), 1 an expectation failed or the
run stopped on a safety event, 2 invalid input. Errors are printed as
messages, never as bare tracebacks (``REHABKIT_DEBUG=1`` shows them).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import traceback
from pathlib import Path

from rehabkit.cli import exits
from rehabkit.cli.exits import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_INVALID, EXIT_OK, refuse, unwritable

# (the core, and pydantic with it, is imported by main() and the commands, not with this module: the collector's
# thresholds entry() sets hold by then)


def _err(msg: str) -> None:
    print(msg, file=sys.stderr)


class _PandasNotNow:
    """A meta-path finder refusing ``pandas`` while it is on ``sys.meta_path`` (see :func:`_pyarrow_without_pandas`)."""

    @staticmethod
    def find_spec(name: str, path=None, target=None):
        if name.partition(".")[0] == "pandas":
            raise ModuleNotFoundError("pandas is not imported for pyarrow's type checks", name=name)
        return None


def _pyarrow_without_pandas() -> None:
    """Spare a run pandas' import (~0.2 s of the main job's ~1.1 s): pyarrow, under Rerun, imports pandas at its
    first array only to ask whether the array is a pandas object, and nothing a run logs is. pyarrow asks once per
    process, so it is asked now with pandas out of reach, then pandas is put back: anyone may import it afterwards,
    and pyarrow still converts pandas objects (through their ``__arrow_array__``, or importing pandas when asked to
    convert from or to it)."""
    if "pandas" in sys.modules:
        return
    import numpy as np
    import pyarrow as pa

    sys.meta_path.insert(0, _PandasNotNow)
    try:
        pa.array(np.zeros(1))
    finally:
        sys.meta_path.remove(_PandasNotNow)


def cmd_run(args: argparse.Namespace) -> int:
    from rehabkit.api import run_scenario
    from rehabkit.cli.run_report import run_report

    _pyarrow_without_pandas()

    out = Path(args.out) if args.out else Path("out") / Path(args.scenario).stem
    made = not out.exists()
    from rehabkit.cli.audit import killed_leftovers

    if left := killed_leftovers(out):  # (a run over it would overwrite what is left of the killed one)
        return refuse(f"error: --out {out} holds a killed run that was not recovered ({', '.join(left)}): "
                      f"`rehabkit recover {out}` makes it a run folder; or choose another --out", "out-killed-run",
                      "--out")
    if (why := unwritable(out)) is not None:
        return refuse(why, "out-unwritable", "--out")
    sets = [*args.set, "ros.bag=true"] if args.bag else args.set
    try:
        result = run_scenario(args.scenario, overrides=sets, out_dir=out, spawn=args.spawn, progress=True)
    except Exception:
        if made and out.is_dir() and not any(out.iterdir()):  # refused before it ran: no empty folder left behind
            out.rmdir()
        raise
    print(run_report(result.summary, out))
    if result.refusal is not None:  # the scenario as written could not be planned: bad input, said where
        _err(str(result.refusal))
        return EXIT_INVALID
    return result.exit_code  # (how it ended: completed 0/1, stopped 1, faults 3/4, interrupted 130/143)


def cmd_sweep(args: argparse.Namespace) -> int:
    from rehabkit.sweep.engine import run_sweep

    if args.out and (why := unwritable(Path(args.out))) is not None:
        _err(why)
        return EXIT_INVALID
    study = None
    if args.bids_study and not args.bids:
        _err("error: --bids-study describes the dataset --bids DATASET makes: give --bids too")
        return EXIT_INVALID
    if args.bids:  # (the dataset's folder and its study checked before anything runs)
        from rehabkit.bids.run_folder import ExportError
        from rehabkit.bids.sidecars import read_study

        if (why := unwritable(Path(args.bids))) is not None:
            _err(why.replace("--out", "--bids"))
            return EXIT_INVALID
        try:
            study = read_study(args.bids_study) if args.bids_study else None
        except ExportError as exc:
            _err(f"error: {exc}")
            return EXIT_INVALID
    bag = args.bag or bool(args.bids)
    try:
        result = run_sweep(args.scenario, args.grid, args.seeds, args.out, address=args.address, workers=args.workers,
                           serial=args.serial, timeout_s=args.timeout, metrics=args.metric, progress=True,
                           overrides=[*args.set, "ros.bag=true"] if bag else args.set,
                           keep_runs=True if args.keep_runs or bag else None)
    except ValueError as exc:  # a malformed --grid or --set
        _err(f"error: {exc}")
        return EXIT_INVALID
    print(result.table())
    how = "serially" if args.serial else f"on Ray ({args.address or 'local'})"
    print(f"\n{len(result.records)} runs: {result.executed} run now {how}, {result.skipped} already done; "
          f"{len(result.failed)} failed; {result.wall_s:.1f} s")
    for rec in result.failed[:10]:
        point = ", ".join(f"{k}={rec[k]}" for k in result.keys)
        print(f"  FAILED  {point + ', ' if point else ''}seed={rec['seed']}: {rec['error']}")
    print(f"wrote {result.out_dir / 'results.parquet'} and {result.out_dir / 'aggregate.csv'}"
          + (" (each run's outputs in runs/<run id>/: the run_dir column)" if result.keeps_runs else ""))
    if args.bids:
        from rehabkit.bids.commands import export_sweep
        from rehabkit.bids.run_folder import ExportError

        try:
            done = export_sweep(result.records, result.out_dir, result.keys, args.bids, study)
        except ExportError as exc:
            _err(f"error: {exc}")
            return EXIT_INVALID
        print(f"wrote {args.bids}: {len(done['added'])} run(s) added, {len(done['skipped'])} already there")
    return EXIT_OK if not result.failed else EXIT_FAILED


def cmd_validate(args: argparse.Namespace) -> int:
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.errors import SetupError

    status = EXIT_OK
    for path in args.scenarios:
        try:
            loaded = load_scenario(path, args.set)
            print(f"{path}: ok{_admission(loaded, args.joints)}{_killed_note(args.out, path)}")
        except ScenarioError as exc:
            _debug_cause(exc)
            _err(str(exc))
            status = EXIT_INVALID
        except (ValueError, SetupError) as exc:
            _err(f"{path}: {exc}")
            status = EXIT_INVALID
    return status


def _killed_note(out: str | None, scenario: str) -> str:
    """A warning line where the folder a run would write to (``--out``, else ``out/<scenario name>``) holds a killed
    run that was not recovered: ``run`` refuses to write over it."""
    from rehabkit.cli.audit import killed_leftovers

    folder = Path(out) if out else Path("out") / Path(scenario).stem
    if not (left := killed_leftovers(folder)):
        return ""
    return (f"\n  WARNING {folder} holds a killed run that was not recovered ({', '.join(left)}): `rehabkit recover "
            f"{folder}` makes it a run folder; `rehabkit run` refuses to write over it until then")


def _joint_table(setup) -> str:
    """The robot's joints in the order a posture lists them, each with its kind and the limits in force, in its own
    unit (what a user writing ``joints: [...]`` needs: the SO-101's order was found only from a wrong count)."""
    import math

    model, lim = setup.robot.model, setup.limits
    rows = []
    for j, name in enumerate(model.joint_names):
        turns = bool(model.revolute[j])
        k, unit, speed, force = (math.degrees(1.0), "°", "°/s", "N·m") if turns else (1.0, " m", " m/s", "N")
        rows.append(f"\n  JOINT   {j + 1}. {name}: {'revolute' if turns else 'prismatic'}, "
                    f"[{lim.lower[j] * k:.4g}, {lim.upper[j] * k:.4g}]{unit}, {lim.velocity[j] * k:.4g}{speed}, "
                    f"{lim.effort[j]:.4g} {force}")
    return "".join(rows)


def _admission(loaded, joints: bool = False) -> str:
    """The run's setup but its backend (robot, narrowed limits, capabilities, admitted targets, plugins) and its
    first plan, as `run` makes them; with a patient or envelope ranges, what became of the fixed targets; with
    ``joints``, the robot's joints in order."""
    from rehabkit.cli.estop import latched_note
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.setup.assembly import assemble
    from rehabkit.core.setup.first_plan import check_first_plan

    notes: list[str] = []  # (what the plugins say as they are built: the run keeps them in its notes)
    setup = assemble(loaded, default_registry(), default_extensions(), upto="plugins",
                     note=lambda t, text: notes.append(text))
    warned = "".join(f"\n  NOTE    {w}" for w in notes)
    warned += "".join(f"\n  PLAN    {w}" for w in check_first_plan(setup))  # (as run says them, before it moves)
    warned += "".join(f"\n  BACKEND {w}" for w in setup.backend_warnings)
    warned += latched_note(setup)
    if joints:
        warned = _joint_table(setup) + warned
    sc = loaded.model
    if sc.patient is None and not sc.safety.joints:
        return warned
    whose = f"patient {sc.patient.id}" if sc.patient is not None else "the safety envelope"
    if not setup.replaced:
        return f" (fixed targets within {whose}'s ranges){warned}"
    replaced = "".join(f"\n  target '{r['target']}' outside the range of {', '.join(r['joints'])}: would be replaced "
                       f"by the nearest admissible posture ({1e3 * r['moved_m']:.1f} mm away)" for r in setup.replaced)
    return replaced + warned


def cmd_plugins(args: argparse.Namespace) -> int:
    from rehabkit.core.plugins.registry import PluginError, default_registry

    reg = default_registry()
    if args.fields:
        from rehabkit.cli.plugin_reference import plugin_reference
        from rehabkit.core.kinds.names import suggest
        from rehabkit.core.plugins.hookspecs import KINDS

        found = [p for p in (reg.find(kind, args.fields) for kind in KINDS) if p is not None]
        if not found:
            installed = [kind for kind in KINDS if args.fields in reg.names(kind)]
            if installed:  # installed, and it does not load: why, not "no such plugin"
                try:
                    reg.get(installed[0], args.fields)
                except PluginError as exc:
                    _err(f"error: {installed[0]} '{args.fields}' is installed but does not load: {exc}")
                    return EXIT_INVALID
            names = sorted({n for kind in KINDS for n in reg.names(kind)})
            _err(f"error: no plugin named '{args.fields}'{suggest(args.fields, names)}")
            return EXIT_INVALID
        print("\n\n".join(plugin_reference(p) for p in found))
        return EXIT_OK
    conflicts = reg.load_all()  # listing them is the one place every plugin is imported
    if args.json:
        print(json.dumps([
            {"kind": p.kind, "name": p.name, "package": p.provider.package, "version": p.provider.version,
             "description": p.description, "fields": [dict(zip(("name", "type", "default"), f)) for f in p.fields()]}
            for p in reg.all()
        ], indent=2))
        return EXIT_OK
    for p in reg.all():
        print(f"{p.kind:<10} {p.name:<16} {p.provider.package} {p.provider.version}  — {p.description}")
        for name, typ, default in p.fields():
            print(f"{'':<12}{name}: {typ} = {default}")
    for b in reg.broken:
        print(f"BROKEN     {b.provider.entry_point:<16} {b.provider.package} {b.provider.version}  — {b.error}")
    for text in conflicts:
        print(f"CONFLICT   {text}")
    from rehabkit.core.plugins.lifecycle import default_extensions

    extensions = default_extensions()
    owned: dict[str, list[str]] = {}
    for section, (owner, _) in extensions.sections(reg).items():
        owned.setdefault(owner, []).append(f"{section}:")
    for name in extensions.names():  # the layers around every run, and the scenario sections each owns
        print(f"{'extension':<10} {name:<16} " + (f"sections {', '.join(owned[name])}" if name in owned else ""))
    for b in extensions.broken:
        print(f"BROKEN     extension {b.name:<6} — {b.error}")
    return EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.json_schema import scenario_json_schema
    from rehabkit.core.scenario.models import scenario_model

    registry = default_registry()
    registry.load_all()
    files = [name for name, (_, section) in default_extensions().sections(registry).items() if section.file]
    print(json.dumps(scenario_json_schema(scenario_model(registry), files), indent=2))
    return EXIT_OK


def parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser. ``only="run"``: the parser as far as ``rehabkit run ARGS`` goes (the top level and
    ``run``: the same parse and the same messages for those arguments), without the other commands' sub-parsers and
    the modules that make them (~5 ms of every run's start)."""
    from rehabkit.core.version import __version__

    p = argparse.ArgumentParser(prog="rehabkit", description=" ".join(__doc__.split("\n\n")[0].split()))
    p.add_argument("--version", action="version", version=f"rehabkit {__version__}")
    p.add_argument("--debug", action="store_true",
                   help="print the traceback behind an error, a plugin's own code included (as REHABKIT_DEBUG=1)")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a scenario; writes DIR/run.rrd and DIR/summary.json")
    r.add_argument("scenario")
    r.add_argument("--out", metavar="DIR", help="output folder (default: out/<scenario name>)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value")
    r.add_argument("--spawn", action="store_true", help="also stream to a Rerun viewer")
    r.add_argument("--bag", action="store_true", help="also write run.mcap, a ROS 2 bag of the run (ros.bag)")
    r.set_defaults(func=cmd_run)
    if only == "run":
        return p
    w = sub.add_parser("sweep", help="run a scenario over a grid of settings x seeds, on Ray; resumable")
    w.add_argument("scenario")
    w.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a setting and its values (YAML each); adds to the scenario's sweep: block")
    w.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a setting every run has")
    w.add_argument("--keep-runs", action="store_true",
                   help="each run's outputs in DIR/runs/<run id>/ (sweep.keep_runs)")
    w.add_argument("--bag", action="store_true", help="each run's ROS 2 bag: DIR/runs/<run id>/run.mcap (ros.bag, "
                                                      "--keep-runs)")
    w.add_argument("--seeds", type=int, default=None, help="runs per grid point (scenario seeds 0..N-1)")
    w.add_argument("--out", metavar="DIR", help="sweep folder (default: out/sweep_<scenario name>); resumes there")
    w.add_argument("--address", help="an existing Ray cluster, e.g. ray://head:10001 (default: a local Ray)")
    w.add_argument("--workers", type=int, default=None, help="CPUs of the local Ray (default: all)")
    w.add_argument("--serial", action="store_true", help="run one after the other in this process, no Ray")
    w.add_argument("--timeout", type=float, default=None, metavar="S", help="per-run limit [s]")
    w.add_argument("--metric", action="append", default=[], help="also show this metric in the aggregate")
    w.add_argument("--bids", metavar="DATASET", help="the runs into a Motion-BIDS dataset, each simulated person a "
                                                     "participant (keeps each run and its bag: --bag)")
    w.add_argument("--bids-study", metavar="FILE", help="the dataset's study description (as export bids --study)")
    w.set_defaults(func=cmd_sweep)
    from rehabkit.cli.replay import add_parser as add_replay

    add_replay(sub)
    v = sub.add_parser("validate", help="check scenario files without running them (and their fixed targets "
                                         "against a patient's ranges)")
    v.add_argument("scenarios", nargs="+")
    v.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    v.add_argument("--joints", action="store_true", help="list the robot's joints in the order a posture gives "
                                                          "them, each with its kind and limits in force")
    v.add_argument("--out", metavar="DIR", help="the folder a run would write to (default: out/<scenario name>): "
                                                 "warned of when it holds a killed run not yet recovered")
    v.set_defaults(func=cmd_validate)
    pl = sub.add_parser("plugins", help="list installed plugins and their settings")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--fields", metavar="NAME", help="the reference of one plugin: every setting with its type, "
                                                       "default and description, and the metrics it reports")
    pl.set_defaults(func=cmd_plugins)
    sc = sub.add_parser("schema", help="print the JSON Schema of scenarios (for editors)")
    sc.set_defaults(func=cmd_schema)
    from rehabkit.cli.bridge import add_parser as add_bridge

    add_bridge(sub)
    from rehabkit.cli.drives import add_parser as add_drives

    add_drives(sub)
    from rehabkit.cli.audit import add_parser as add_audit

    add_audit(sub)
    from rehabkit.cli.audit import add_recover_parser

    add_recover_parser(sub)
    from rehabkit.cli.estop import add_parser as add_estop

    add_estop(sub)
    from rehabkit.cli.keys import add_parser as add_keys

    add_keys(sub)
    from rehabkit.cli.assess import add_parser as add_assess

    add_assess(sub)
    from rehabkit.cli.safety_report import add_parser as add_safety_report

    add_safety_report(sub)
    from rehabkit.bids.commands import add_parser as add_bids

    add_bids(sub)
    return p


def _parse(argv: list[str]) -> argparse.Namespace:
    """``argv`` parsed: ``rehabkit run ARGS`` by :func:`parser` ``(only="run")`` where all of ARGS are run's (its
    errors, and ``--help``, are its sub-parser's own: the same), anything else by the whole parser, which says what the
    top level says (``unrecognized arguments``, with the list of commands in its usage)."""
    if argv[:1] == ["run"]:
        args, rest = parser(only="run").parse_known_args(argv)
        if not rest:
            return args
    return parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    import warnings

    warnings.formatwarning = lambda msg, category, *a, **k: f"warning: {msg}\n"
    args = _parse(sys.argv[1:] if argv is None else list(argv))
    from rehabkit.core.plugins.registry import PluginError
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.setup.errors import SetupError

    if args.debug:
        os.environ["REHABKIT_DEBUG"] = "1"
    exits.last_refusal = None  # (this command's refusal, if it makes one: not an earlier command's in this process)
    try:
        return args.func(args)
    except ScenarioError as exc:
        _debug_cause(exc)
        _err(str(exc))
        return EXIT_INVALID
    except PluginError as exc:
        _err(f"error: {exc}")
        return EXIT_INVALID
    except KeyboardInterrupt as exc:  # (a run's loop takes its own: here, before one began or outside a run)
        _err("interrupted" + (" (SIGTERM)" if getattr(exc, "signal", None) == "SIGTERM" else "")
             + "; nothing was written")
        return 143 if getattr(exc, "signal", None) == "SIGTERM" else EXIT_INTERRUPTED
    except BrokenPipeError:  # e.g. `rehabkit plugins | head`: the reader left, nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:  # the last line of defence: a message, and the traceback only on request
        if isinstance(exc, SetupError):
            _err(f"error: {exc}")
            return EXIT_INVALID
        if os.environ.get("REHABKIT_DEBUG"):
            traceback.print_exc()
        _err(f"internal error: {type(exc).__name__}: {exc} (--debug for the traceback)")
        return EXIT_FAILED


def _debug_cause(exc: BaseException) -> None:
    """With ``REHABKIT_DEBUG=1``: the traceback of what a plugin raised behind a located error (its own code)."""
    if os.environ.get("REHABKIT_DEBUG") and exc.__cause__ is not None:
        traceback.print_exception(exc.__cause__)


def entry() -> None:
    """The ``rehabkit`` command: :func:`main`, then the exit, without the interpreter's last collections."""
    # the engines' imports and a run's set-up make ~10^6 objects that live as long as the process: the collector's
    # default thresholds walk them all again twice on the way (~40 ms of a 1 s run); its youngest generation is
    # still swept, every 10^5 allocations, and a run's loop sweeps and freezes it as it starts. Set before the core
    # and pydantic are imported (by main(): this module imports neither), whose imports it spares ~5 ms of collections
    gc.set_threshold(100_000, 50, 1000)
    code = main()
    # the collections at interpreter exit walk every object the engines made: ~0.2 s of a 1.3 s run. Frozen, they
    # are left to the OS; atexit handlers (Ray, Rerun) still run, and every output is already whole and closed.
    # Not with OMPL loaded: nanobind, its binding layer, reports every object left uncollected at exit as a leak.
    if "ompl" not in sys.modules:
        gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    entry()
