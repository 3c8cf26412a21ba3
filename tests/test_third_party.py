"""Separately installed packages add plugins through their own entry points: a planner (examples/third_party_plugin)
and one plugin of every other kind (examples/lab_plugins), installed together as a user would."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from tests.conftest import ROOT
from tests.located import located

# one worker installs both packages once for the module's tests (~7 s a pip install)
pytestmark = pytest.mark.xdist_group("third-party")

EXAMPLE = ROOT / "examples" / "third_party_plugin"
LAB = ROOT / "examples" / "lab_plugins"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """Both example packages installed into a site directory of their own; the environment that sees them."""
    target = tmp_path_factory.mktemp("site")
    # built from copies: setuptools writes build/ and *.egg-info beside the sources, and the suite leaves the work
    # tree as it found it (no build isolation: the installed setuptools builds them, several times faster)
    sources = tmp_path_factory.mktemp("sources")
    copies = [shutil.copytree(p, sources / p.name, ignore=shutil.ignore_patterns("build", "*.egg-info"))
              for p in (EXAMPLE, LAB)]
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                          "--target", str(target), *map(str, copies)], capture_output=True, text=True)
    assert pip.returncode == 0, pip.stderr
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(target), os.environ.get("PYTHONPATH", "")])}
    listed = subprocess.run([sys.executable, "-m", "rehabkit.cli", "plugins"], capture_output=True, text=True, env=env)
    return env, listed.stdout


def test_third_party_plugin_installs_and_runs_in_a_scenario(tmp_path, installed):
    env, listed = installed
    assert "min-jerk         rehabkit-minjerk 0.1.0" in listed

    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "rehabkit.cli", "run",
                          str(EXAMPLE / "scenarios" / "hit_minjerk.yaml"), "--out", str(out)],
                         capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["plugins"]["planner"] == {"type": "min-jerk", "package": "rehabkit-minjerk", "version": "0.1.0"}
    assert summary["metrics"]["final_position_error_m"] < 0.005

    # without the package the same scenario is a clear error, not a crash
    missing = subprocess.run([sys.executable, "-m", "rehabkit.cli", "validate",
                              str(EXAMPLE / "scenarios" / "hit_minjerk.yaml")], capture_output=True, text=True)
    # refused at the planner's type, the plugin the scenario names (its `type: min-jerk`, line 5) not installed
    assert (missing.returncode, [x[1:] for x in located(missing.stderr)]) == (2, [(5, 9, "planner.type")])


def test_a_plugin_of_every_kind_installs_and_runs_together(tmp_path, installed):
    env, listed = installed
    for kind, name in (("robot", "planar-arm"), ("controller", "saturating-pd"), ("sensor", "hand-position"),
                       ("backend", "rigid-body"), ("patient", "relaxed-arm")):
        assert f"{kind:<10} {name:<16} rehabkit-lab-example 0.1.0" in listed, name
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "rehabkit.cli", "run", str(LAB / "scenarios" / "planar_lab.yaml"),
                          "--out", str(out)], capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    summary = json.loads((out / "summary.json").read_text())
    used = {kind: summary["plugins"][kind]["package"] for kind in ("robot", "backend", "controller")}
    assert used == dict.fromkeys(used, "rehabkit-lab-example")
    m = summary["metrics"]
    assert m["final_position_error_m"] < 0.005 and m["tracking_max_deg"] < 2  # reached through the person's pull
    assert 0.6 < m["hand_marker_error_rms_mm"] < 1.2  # 0.5 mm per axis: √3 · 0.5 = 0.87 mm
    assert m["person_torque_max_nm"] > 0.5 and 0 <= m["pd_saturated_share"] < 0.5
