"""pytest plugin (entry point ``pytest11``): scenarios are tests.

* ``pytest scenarios/`` collects every YAML file with top-level ``robot`` and
  ``expect`` sections as one test item; it passes when the run meets all its
  expectations without an unexpected safety stop.
* The ``run_scenario`` fixture runs a scenario with overrides, for users' own
  parametrised tests::

      def test_faster_segments(run_scenario):
          result = run_scenario("scenarios/hit_roundtrip.yaml", planner__segment_durations=[1.5] * 4)
          assert result.metrics["tracking_rms_deg"] < 1.0

  Keyword overrides use ``__`` for dots; ``overrides={"a.b": 1}`` works too.
  Outputs go to the test's ``tmp_path``.
* The ``scenario_run`` fixture gives the run of a scenario file as written (no overrides), made once per test
  session and shared with that file's scenario test: tests that examine the scenario's own run in detail don't
  run it again, and neither does the scenario test after them::

      def test_the_round_trip_is_smooth(scenario_run):
          result = scenario_run("scenarios/hit_roundtrip.yaml")  # written to result.out_dir
          assert result.metrics["sparc"] > -2.0

  The result is shared: read it, don't change it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from rehabkit.core.safety.estop import own_state

_RUNS = pytest.StashKey[dict[Path, Any]]()


def shared_run(config: pytest.Config, path: str | Path):
    """The session's run of scenario ``path`` as written, made now if nobody has asked for it yet."""
    from rehabkit.api import run_scenario

    path = Path(path).resolve()
    runs = config.stash.setdefault(_RUNS, {})
    if path not in runs:
        out = Path(config._tmp_path_factory.mktemp(path.stem))  # type: ignore[attr-defined]
        with own_state(out / "state"):  # a scenario test starts with no e-stop latched, and leaves none behind
            runs[path] = run_scenario(path, out_dir=out)
    return runs[path]



# libyaml's loader where PyYAML has it (~10x the pure-Python one's speed): collection reads every YAML file under the
# test paths, in every pytest-xdist worker; the scenario itself is loaded by rehabkit's loader, with its marks
_FAST_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _read_head(path: Path):
    """A YAML file's top level, read as plain data (no marks: only to tell what the file is)."""
    return yaml.load(path.read_text(), Loader=_FAST_LOADER)  # noqa: S506 (a safe loader: libyaml's SafeLoader)


def _is_scenario(path: Path) -> bool:
    """A whole scenario with expectations: ``robot:`` and ``expect:``, given in the file or by the files it
    ``extends:`` (a scenario file that fails to read is collected: its test says why)."""
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.source import read_with_extends

    try:
        head = _read_head(path)
    except (OSError, yaml.YAMLError, ValueError):
        return False
    if not isinstance(head, dict) or not ({"robot", "extends"} & set(head)):
        return False
    if "extends" in head:
        try:
            head = read_with_extends(path).data
        except ScenarioError:
            return "expect" in head
    return "robot" in head and "expect" in head


def pytest_collect_file(parent: pytest.Collector, file_path: Path):
    if file_path.suffix in (".yaml", ".yml") and not file_path.name.startswith("_") and _is_scenario(file_path):
        return ScenarioFile.from_parent(parent, path=file_path)
    return None


def group(path: str | Path) -> str:
    """The ``xdist_group`` of a scenario's shared run: a test that reads it with ``scenario_run`` and is marked
    ``@pytest.mark.xdist_group(group(path))`` runs on the same pytest-xdist worker as the scenario's own test
    (``--dist loadgroup``), so the run is made once."""
    return f"scenario:{Path(path).stem}"


class ScenarioFile(pytest.File):
    def collect(self):
        item = ScenarioItem.from_parent(self, name=self.path.stem)
        item.add_marker(pytest.mark.xdist_group(group(self.path)))  # with the tests that read its run
        yield item
        if isinstance(head := _read_head(self.path), dict) and head.get("sweep"):  # (its own sweep: block)
            yield SweepItem.from_parent(self, name=f"{self.path.stem}[sweep]")


class ScenarioFailedError(Exception):
    """A scenario's expectations were not met."""


class ScenarioItem(pytest.Item):
    """One scenario run; fails with the unmet expectations and safety events."""

    def runtest(self) -> None:
        result = shared_run(self.config, self.path)  # once per session: a test may have examined it already
        self.user_properties.append(("real_time_factor", result.summary["metrics"]["real_time_factor"]))
        if not result.passed:
            raise ScenarioFailedError(result)

    def repr_failure(self, excinfo, style=None):
        from rehabkit.core.scenario.errors import ScenarioError

        if isinstance(excinfo.value, ScenarioFailedError):
            summary = excinfo.value.args[0].summary
            lines = [f"scenario {self.path.name} failed:"]
            for e in summary["expectations"]:
                if not e["passed"]:
                    lines.append(f"  {e['metric']} = {e['value']}  (expected {e['bound']})" +
                                 (f" — {e['reason']}" if e.get("reason") else ""))
            lines += [f"  safety: {ev['message']}" for ev in summary["safety"]["events"]]
            return "\n".join(lines)
        if isinstance(excinfo.value, ScenarioError):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, 0, f"scenario: {self.path.name}"


class SweepItem(pytest.Item):
    """A scenario's declared ``sweep:``, with its ``test_seeds`` (serially, in this process): every run ends
    without an error and meets the scenario's expectations."""

    def runtest(self) -> None:
        from rehabkit.core.scenario.loader import load_scenario
        from rehabkit.sweep.engine import run_sweep

        spec = load_scenario(self.path).model.sweep
        out = Path(self.config._tmp_path_factory.mktemp(f"{self.path.stem}_sweep"))  # type: ignore[attr-defined]
        result = run_sweep(self.path, seeds=spec.test_seeds or spec.seeds, out_dir=out, serial=True)
        bad = [r for r in result.records if r["error"] is not None or not r["passed"]]
        if bad:
            lines = [", ".join(f"{k}={r[k]}" for k in result.keys) + f", seed={r['seed']}: "
                     + (r["error"] or "expectations not met: " + ", ".join(
                         k[7:] for k, v in r.items() if k.startswith("expect.") and v is False)) for r in bad]
            raise AssertionError(f"sweep of {self.path.name}: {len(bad)} of {len(result.records)} runs failed\n"
                                 + "\n".join(lines))

    def reportinfo(self):
        return self.path, 0, f"sweep: {self.path.name}"


@pytest.fixture
def run_sweep(tmp_path: Path) -> Callable[..., Any]:
    """Run a sweep (``rehabkit.sweep.engine.run_sweep`` arguments) into a fresh folder; returns its result."""
    from rehabkit.sweep.engine import run_sweep as _sweep

    counter = iter(range(1_000_000))

    def sweep(path: str | Path, grid: Any = None, seeds: int | None = None, **kw: Any):
        kw.setdefault("serial", True)
        return _sweep(path, grid, seeds, tmp_path / f"sweep{next(counter)}", **kw)

    return sweep


@pytest.fixture(scope="session")
def scenario_run(pytestconfig: pytest.Config) -> Callable[[str | Path], Any]:
    """``scenario_run(path)``: the run of a scenario file as written, once per session (shared with its scenario
    test); a :class:`rehabkit.core.results.summary.RunResult` with its outputs in ``out_dir``."""
    return lambda path: shared_run(pytestconfig, path)


@pytest.fixture
def run_scenario(tmp_path: Path, request: pytest.FixtureRequest) -> Callable[..., Any]:
    """Run a scenario file with overrides; returns a :class:`rehabkit.core.results.summary.RunResult`. A relative
    path is from the current directory, or else from the test file's folder (``run_scenario("planar_reach.yaml")``
    beside the test runs wherever pytest starts)."""
    from rehabkit.api import run_scenario as _run

    counter = iter(range(1_000_000))

    def run(path: str | Path, overrides: dict[str, Any] | None = None, write: bool = True, **kw: Any):
        path = Path(path)
        if not path.is_absolute() and not path.exists() and (request.path.parent / path).exists():
            path = request.path.parent / path
        merged = dict(overrides or {})
        merged.update({k.replace("__", "."): v for k, v in kw.items()})
        out = tmp_path / f"run{next(counter)}" if write else None
        return _run(path, merged, out_dir=out)

    return run
