"""Sweeps: the grid, serial against Ray row for row, resuming a killed sweep, failing and hanging runs."""

import csv
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.sweep.engine import run_sweep
from rehabkit.sweep.grid import expand, parse_grid
from rehabkit.sweep.tables import reproducible
from tests.conftest import SCENARIOS

# one Ray at a time on this machine: the sweeps that start one run on the same pytest-xdist worker
pytestmark = pytest.mark.xdist_group("ray")

TRIAL = SCENARIOS / "lexos_planner_trial.yaml"
HIT = SCENARIOS / "hit_roundtrip.yaml"


def test_grid_values_are_yaml_and_the_product_is_in_grid_order_with_stable_ids():
    grid = parse_grid(["planner.type=voxel-astar,voxel-hill", "planner.segment_durations=[1, 2],[3, 4]"])
    assert grid == {"planner.type": ["voxel-astar", "voxel-hill"], "planner.segment_durations": [[1, 2], [3, 4]]}
    runs = expand(TRIAL, grid, seeds=3)
    assert len(runs) == 12 and len({r.run_id for r in runs}) == 12
    assert [r.seed for r in runs[:4]] == [0, 1, 2, 0] and runs[3].point[1][1] == [3, 4]
    assert [r.run_id for r in expand(TRIAL, grid, seeds=3)] == [r.run_id for r in runs]  # stable: resumable
    with pytest.raises(ValueError, match="expected key.path=value1,value2"):
        parse_grid(["planner.type"])
    with pytest.raises(ValueError, match="set by the sweep's seeds"):
        expand(TRIAL, {"seed": [1, 2]}, 2)


def test_a_bad_grid_value_is_refused_before_any_run_with_its_place(tmp_path):
    with pytest.raises(ScenarioError) as err:
        run_sweep(TRIAL, ["planner.type=voxel-astar,voxel-astra"], 2, tmp_path, serial=True)
    (d,) = err.value.diagnostics
    assert d.mark.file == "<--grid planner.type>" and d.path == "planner.type"  # (the grid's, not a --set's)
    assert d.fix.startswith("did you mean 'voxel-astar'")  # (the value the grid meant, nearest first)
    assert not list((tmp_path / "runs").glob("*.json")) if (tmp_path / "runs").exists() else True


def test_serial_and_ray_give_the_same_rows_and_a_second_call_runs_nothing(tmp_path, running_ray):
    grid = ["planner.type=voxel-astar,voxel-beam"]
    serial = run_sweep(TRIAL, grid, 3, tmp_path / "serial", serial=True)
    ray = run_sweep(TRIAL, grid, 3, tmp_path / "ray", workers=2)
    assert sys.modules["ray"].is_initialized()  # (a sweep leaves a Ray it did not start running)
    assert serial.executed == ray.executed == 6 and not serial.failed and not ray.failed
    assert reproducible(serial.records) == reproducible(ray.records)
    # different start/goal pairs per seed; the same pairs for both planners; A* never longer than beam
    lengths = {(r["planner.type"], r["seed"]): r["metric.decimated_path_length_m"] for r in serial.records}
    assert len({lengths["voxel-astar", s] for s in range(3)}) == 3
    assert all(lengths["voxel-astar", s] <= lengths["voxel-beam", s] + 1e-9 for s in range(3))
    agg = {a["planner.type"]: a for a in serial.aggregate}
    assert agg["voxel-astar"]["runs"] == 3 and agg["voxel-astar"]["decimated_path_length_m.n"] == 3
    astar = [lengths["voxel-astar", s] for s in range(3)]  # the spread across seeds: the sample's
    assert agg["voxel-astar"]["decimated_path_length_m.std"] == pytest.approx(np.std(astar, ddof=1))
    assert (tmp_path / "serial" / "results.parquet").stat().st_size > 0
    with open(tmp_path / "serial" / "aggregate.csv", newline="") as f:
        assert next(csv.reader(f))[:4] == ["planner.type", "runs", "errors", "passed"]  # (its header)
    again = run_sweep(TRIAL, grid, 3, tmp_path / "serial", serial=True)
    assert again.executed == 0 and again.skipped == 6 and reproducible(again.records) == reproducible(serial.records)


@pytest.mark.parametrize("running", [False, True])
def test_a_sweep_stops_the_ray_it_started_and_only_that(monkeypatch, running):
    """Ray's start and stop around a sweep's runs, Ray itself stood in for (starting one takes seconds; the module's
    other Ray sweeps share one): started and stopped where none ran, left alone where one did."""
    import ray

    from rehabkit.sweep import engine

    said: list[str] = []
    monkeypatch.setattr(ray, "is_initialized", lambda: running)
    monkeypatch.setattr(engine, "start_ray", lambda address, workers: said.append(f"start {workers}"))
    monkeypatch.setattr(ray, "shutdown", lambda: said.append("stop"))
    monkeypatch.setattr(ray, "cluster_resources", lambda: {"CPU": 2.0})
    monkeypatch.setattr(ray, "remote", lambda **options: lambda f: f)
    engine._on_ray([], str(TRIAL), 10.0, None, 2, lambda s, row: None, lambda s: None)
    assert said == ([] if running else ["start 2", "stop"])


def test_a_killed_sweep_resumes_without_redoing_finished_runs(tmp_path):
    out = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "rehabkit.cli", "sweep", str(TRIAL), "--grid", "planner.type=voxel-astar,voxel-hill",
           "--seeds", "6", "--serial", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(list((out / "runs").glob("*.json"))) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)  # no chance to tidy up
    finally:
        proc.wait()
    finished = {f.name for f in (out / "runs").glob("*.json")}
    assert 3 <= len(finished) < 12 and not (out / "results.parquet").exists()
    resumed = run_sweep(TRIAL, ["planner.type=voxel-astar,voxel-hill"], 6, out, serial=True)
    assert resumed.skipped == len(finished) and resumed.executed == 12 - len(finished)
    assert len(resumed.records) == 12 and not resumed.failed
    fresh = run_sweep(TRIAL, ["planner.type=voxel-astar,voxel-hill"], 6, tmp_path / "fresh", serial=True)
    assert reproducible(resumed.records) == reproducible(fresh.records)


@pytest.fixture(scope="module")
def running_ray():
    """One local Ray for the module's Ray sweeps (its start-up and shut-down take seconds each), started as a sweep
    starts it; sweeps use a running Ray and leave it running (a sweep's own start and stop:
    test_a_sweep_stops_the_ray_it_started_and_only_that). Both workers have run a short HIT run first: a worker's
    first run also imports the plugins, which on this loaded VM took a 0.5 s run past the hanging-run test's
    timeout (then 5 s)."""
    import ray

    from rehabkit.sweep.engine import start_ray
    from rehabkit.sweep.execute import execute

    start_ray(workers=2)
    warm = ray.remote(num_cpus=1)(execute)
    assert all(row["error"] is None for row in ray.get(
        [warm.remote(str(HIT), {"duration": 0.05, "logging.rrd": False}) for _ in range(2)]))
    yield
    ray.shutdown()


@pytest.mark.parametrize("mode", ["serial", "ray"])
def test_a_crashing_run_is_recorded_with_its_error_and_the_others_complete(tmp_path, mode, request):
    if mode == "ray":
        request.getfixturevalue("running_ray")
    # a whole-body controller on an arm: valid settings, but the run cannot be put together
    grid = {"controller": [{"type": "clik-pd"}, {"type": "qp-stack", "levels": [{"tasks": [{"type": "com"}]}]}]}
    result = run_sweep(TRIAL, {"planner.type": ["voxel-astar"], **grid}, 2, tmp_path, serial=mode == "serial",
                       workers=2)  # (the scenario's own grid has four planners; one is enough here)
    assert len(result.records) == 4
    labels = [r["controller"] for r in result.records]  # whole sections: by type and settings, short
    assert labels[:2] == ["clik-pd"] * 2 and labels[2] == labels[3] and labels[2].startswith("qp-stack #")
    ok, crashed = result.records[:2], result.records[2:]
    assert all(r["error"] is None and r["passed"] for r in ok)
    assert all(r["error"] is not None and r["error_type"] == "PluginSetupError" and not r["passed"]
               and r["error_missing"] == ["FloatingBase"] for r in crashed)  # (the qp-stack controller's need)
    assert [a["errors"] for a in result.aggregate] == [0, 2] and len(result.failed) == 2


def test_a_grid_over_whole_plugin_sections_as_the_readme_writes_it(tmp_path):
    """`--grid 'controller={type: joint-pd, kp: 300},{type: assist-as-needed}'` on HIT: each value a whole
    section (the second plugin takes none of the first's settings, nor the scenario's), labelled short."""
    from rehabkit.sweep.grid import parse_grid

    readme = (SCENARIOS.parent / "README.md").read_text()
    (raw,) = re.findall(r"--grid '(controller=\{type: joint-pd[^']*)'", readme)
    grid = parse_grid([raw])
    assert grid == {"controller": [{"type": "joint-pd", "kp": 300}, {"type": "assist-as-needed"}]}
    result = run_sweep(HIT, {"duration": [1.0], **grid}, 1, tmp_path, serial=True)
    assert [r["controller"] for r in result.records] == ["joint-pd kp=300", "assist-as-needed"]
    assert [r["error"] for r in result.records] == [None, None]


def test_a_finished_run_is_freed_without_a_full_collection_and_a_failed_one_is_collected(monkeypatch):
    """A sweep's worker runs one scenario after another: each run's scene must go with it. A run that finishes is
    freed by reference counting (a full collection costs ~50 ms a run); one that raised is collected (its
    traceback holds it)."""
    import gc

    from rehabkit.sweep.execute import execute

    full, collect = [], gc.collect

    def counting(*generation):
        if not generation:
            full.append(generation)
        return collect(*generation)

    monkeypatch.setattr(gc, "collect", counting)
    ok = execute(str(HIT), {"duration": 0.05, "logging.rrd": False})
    assert ok["error"] is None and [g for g in full if not g] == []
    failed = execute(str(TRIAL), {"controller": {"type": "qp-stack", "levels": [{"tasks": [{"type": "com"}]}]}})
    assert failed["error_missing"] == ["FloatingBase"] and [g for g in full if not g] == [()]


# The two tests below stop a run under way on Ray, and Ray stops it by killing its worker: a worker started in its place
# imports Ray, rehabkit and the plugins again (seconds of CPU each). So they come last, the run stopped by Ctrl-C
# last of all (the hanging-run test's short run must find its worker warm, within its timeout); the Ray sweeps
# before them (pytest runs a module's tests in the order written) keep the workers the module's Ray started.


@pytest.mark.realtime  # (a wall-clock timeout, and its bound: what only real time shows)
@pytest.mark.parametrize("mode", ["serial", "ray"])
def test_a_hanging_run_is_stopped_and_recorded_and_the_sweep_goes_on(tmp_path, mode, request):
    if mode == "ray":
        request.getfixturevalue("running_ray")
    # 300 s of simulated HIT take far longer than the 2 s allowed; the 0.2 s run finishes (in ~0.2 s: a tenth of the
    # timeout, a larger share to spare than the 0.5 s run had of 3 s; the stopped run's timeout is the test's CPU)
    result = run_sweep(HIT, ["duration=0.2,300"], 1, tmp_path, serial=mode == "serial", workers=2, timeout_s=2)
    by = {r["duration"]: r for r in result.records}  # (a grid of numbers: a column of numbers)
    assert by[0.2]["error"] is None and by[0.2]["metric.sim_time_s"] == pytest.approx(0.2)
    assert by[300]["error_type"] == "RunTimeoutError" and not by[300]["passed"]
    assert by[300]["wall_time_s"] < 30
    assert [a["errors"] for a in result.aggregate] == [0, 1]


def test_a_ray_sweep_stopped_by_ctrl_c_records_the_run_under_way_as_interrupted(tmp_path, monkeypatch, running_ray):
    """Ctrl-C while a run goes on Ray (raised where the driver waits, once the short run is recorded): the finished
    run kept, the one under way recorded as interrupted and so left to run again on resuming, the Ctrl-C passed on.
    (A Ray sweep lost its runs under way without a word.)"""
    import ray

    from rehabkit.sweep.grid import expand
    from rehabkit.sweep.store import RunStore

    wait = ray.wait

    def interrupted_once_one_is_recorded(*args, **kwargs):
        if list((tmp_path / "runs").glob("*.json")):
            raise KeyboardInterrupt
        return wait(*args, **kwargs)

    monkeypatch.setattr(ray, "wait", interrupted_once_one_is_recorded)
    with pytest.raises(KeyboardInterrupt):  # (300 s of HIT: seconds of wall time, under way at the Ctrl-C)
        run_sweep(HIT, ["duration=0.2,300"], 1, tmp_path, workers=2)
    rows = {r.point[0][1]: r for r in expand(HIT, {"duration": [0.2, 300]}, 1)}
    short, cut = (json.loads((tmp_path / "runs" / f"{rows[d].run_id}.json").read_text()) for d in (0.2, 300))
    assert short["error"] is None and short["metrics"]["sim_time_s"] == pytest.approx(0.2)
    assert cut["ended"]["how"] == "interrupted" and cut["ended"]["signal"] == "SIGINT" and not cut["passed"]
    assert set(RunStore(tmp_path).done(list(rows.values()))) == {rows[0.2].run_id}  # (resuming runs it again)
