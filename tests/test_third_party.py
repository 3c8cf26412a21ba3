"""A separately installed package adds a planner through its own entry point."""

import json
import os
import subprocess
import sys

from tests.conftest import ROOT

EXAMPLE = ROOT / "examples" / "third_party_plugin"


def test_third_party_plugin_installs_and_runs_in_a_scenario(tmp_path):
    target = tmp_path / "site"
    # (no build isolation: the installed setuptools builds it, 1.6 s; an isolated build environment took 6 s)
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                          "--target", str(target), str(EXAMPLE)], capture_output=True, text=True)
    assert pip.returncode == 0, pip.stderr
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(target), os.environ.get("PYTHONPATH", "")])}

    listed = subprocess.run([sys.executable, "-m", "rehabkit.cli", "plugins"], capture_output=True, text=True, env=env)
    assert "min-jerk         rehabkit-minjerk 0.1.0" in listed.stdout

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
    assert missing.returncode == 2 and "unknown planner plugin 'min-jerk'" in missing.stderr
