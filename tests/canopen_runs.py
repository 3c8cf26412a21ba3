"""A run on simulated CANopen drives that several tests read, made once per test session: the README's command
(tests/test_canopen_readme.py runs it as written) is the run tests/test_canopen_backend.py compares with MuJoCo's.

Here, not in either test file: pytest imports a test file under its own name (``test_canopen_backend``) and another
test file that imports it gets a second copy (``tests.test_canopen_backend``), whose cache would be a second one."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import can
import pytest

from rehabkit.core.safety.estop import own_state

ROOT = Path(__file__).resolve().parents[1]
# the README's run on simulated drives ("On CANopen drives"), as its command line gives it
README_RUN = ("run", "scenarios/hit_roundtrip.yaml", "--set", "backend.type=canopen", "--set", "rates.control_hz=500",
              "--set", "backend.clock=lockstep")
SHARED = "canopen:readme-run"  # the xdist_group of the tests that read it: one worker, one run
_RUNS = pytest.StashKey[dict[tuple, SimpleNamespace]]()


def cli_run(request: pytest.FixtureRequest, *args: str) -> SimpleNamespace:
    """``rehabkit ARGS --out DIR`` from the repository's root, in this process (tests/test_cli.py's ``cli``), made once
    per session for every test that reads that run (each marked ``xdist_group(SHARED)``): ``done`` (its exit code,
    stdout, stderr), ``result`` (the RunResult the command's ``run_scenario`` returned), ``out`` (the folder it wrote:
    two levels the run made) and ``frames`` (its ``can.asc`` read back by python-can). HIT's 8.5 s on six drives
    costs ~3 s of CPU with its outputs: the README's test and the tracking test read the same run. Shared: read it,
    don't change it."""
    runs = request.config.stash.setdefault(_RUNS, {})
    if args not in runs:
        from rehabkit import api
        from tests.test_cli import cli

        base = request.getfixturevalue("tmp_path_factory").mktemp("cli-run")
        out = base / "not" / "yet"  # (an output folder the run makes: the trace opens before the log)
        results, run = [], api.run_scenario

        def kept(*a, **kw):  # (the command's own call, its result kept as it returns it)
            results.append(run(*a, **kw))
            return results[-1]

        with pytest.MonkeyPatch.context() as patch, own_state(base / "state"):  # (no latch of the asking test's)
            patch.setattr(api, "run_scenario", kept)
            done = cli(*args, "--out", str(out), cwd=ROOT)
        trace = out / "can.asc"
        runs[args] = SimpleNamespace(done=done, result=results[0] if results else None, out=out,
                                     frames=list(can.LogReader(trace)) if trace.exists() else [])
    return runs[args]
