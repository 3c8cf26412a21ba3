"""Installed distributions (dist-info on sys.path): a broken one, a conflicting one."""

import json
import os
import subprocess
import sys

import pytest

from rehabkit.core.plugins.registry import PluginConflictError, PluginLoadError
from tests.conftest import SCENARIOS
from tests.located import set_located, suggested


def fake_dist(site, name, group, entry_name, module, source):
    info = site / f"{name.replace('-', '_')}-1.2.3.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.2.3\n")
    (info / "entry_points.txt").write_text(f"[{group}]\n{entry_name} = {module}\n")
    (site / f"{module}.py").write_text(source)


def rehabkit(site, monkeypatch, *args):
    """``rehabkit ARGS`` as a process with ``site`` on its path sees the installed plugins: run in this process (a
    Python per call cost ~1 s of the suite each), the process-wide registry discovered afresh with ``site`` on the
    path, and put back after the test."""
    from rehabkit.core.plugins import registry
    from tests.test_cli import cli

    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setattr(registry, "_DEFAULT", None)
    return cli(*args)


def registry_seeing(site, monkeypatch):
    """A registry of the plugins installed as this process sees them with ``site`` on its path (the subprocess's
    view, in-process: its errors read as fields)."""
    from rehabkit.core.plugins.discovery import installed_entries
    from rehabkit.core.plugins.registry import PluginRegistry

    monkeypatch.syspath_prepend(str(site))
    return PluginRegistry(installed_entries())


def test_broken_distribution_is_listed_and_the_rest_still_runs(tmp_path, monkeypatch):
    site = tmp_path / "site"
    fake_dist(site, "rehabkit-exo-driver", "rehabkit.robots", "exo", "exo_driver", "import not_a_real_module_xyz\n")
    listed = rehabkit(site, monkeypatch, "plugins")
    assert listed.returncode == 0
    broken = [line for line in listed.stdout.splitlines() if line.startswith("BROKEN")]
    assert broken and "rehabkit-exo-driver 1.2.3" in broken[0] and "not_a_real_module_xyz" in broken[0]
    assert "multi-cubic" in listed.stdout
    run = rehabkit(site, monkeypatch, "run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(tmp_path / "out"),
                   "--set", "duration=0.5", "--set", "expect=null")
    assert run.returncode == 0, run.stderr
    # naming it is a located refusal with its cause, before anything runs
    named = rehabkit(site, monkeypatch, "validate", str(SCENARIOS / "hit_roundtrip.yaml"), "--set", "robot.type=exo")
    assert named.returncode == 2 and "Traceback" not in named.stderr
    assert set_located(named.stderr) == [("robot.type", "robot.type")]
    # its reference: installed, and why it does not load (not "no plugin named 'exo'; did you mean 'exo'")
    fields = rehabkit(site, monkeypatch, "plugins", "--fields", "exo")
    assert fields.returncode == 2 and suggested(fields.stderr) == []
    # what both say: the distribution that installed it and the module its import did not find
    with pytest.raises(PluginLoadError) as not_loaded:
        registry_seeing(site, monkeypatch).get("robot", "exo")
    provider, failure = not_loaded.value.provider, not_loaded.value.failure
    assert (provider.package, provider.version) == ("rehabkit-exo-driver", "1.2.3")
    assert isinstance(failure, ModuleNotFoundError) and failure.name == "not_a_real_module_xyz"


def test_a_run_imports_only_the_plugins_it_names(tmp_path):
    """Discovery reads metadata; ``rehabkit run`` of the HIT round trip imports its robot, planner, controller,
    sensor and backend, and none of the engines other plugins need; a run with no folder imports no Rerun."""
    # first a run with no folder (a sweep's, a notebook's): no recording, so no Rerun imported; then the command as a
    # user runs it, to its exit
    unrecorded = (f"from rehabkit.api import run_scenario; run_scenario({str(SCENARIOS / 'hit_roundtrip.yaml')!r}, "
                  "['duration=0.1', 'expect=null']); print(json.dumps(sorted(m for m in ('rerun', 'pyarrow') "
                  "if m in sys.modules)))")
    code = ("import atexit, json, runpy, sys; atexit.register(lambda: print(json.dumps(sorted(sys.modules)))); "
            f"{unrecorded}; runpy.run_module('rehabkit.cli', run_name='__main__')")
    done = subprocess.run([sys.executable, "-c", code, "run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out",
                           str(tmp_path), "--set", "duration=0.2", "--set", "expect=null"], capture_output=True,
                          text=True, env={**os.environ, "MUJOCO_GL": "egl"})
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout.splitlines()[-1]))
    assert json.loads(done.stdout.splitlines()[0]) == []  # (the run with no folder)
    assert (tmp_path / "run.rrd").stat().st_size > 0 and "rerun" in loaded
    plugins = {m for m in loaded if m.count(".") == 2 and m.startswith("rehabkit_plugins.")}  # modules, not packages
    assert plugins == {"rehabkit_plugins.robots.hit", "rehabkit_plugins.planners.multi_cubic",
                       "rehabkit_plugins.controllers.joint_pd", "rehabkit_plugins.sensors.joint_encoder"}, plugins
    # (nor pandas: pyarrow, under Rerun, would import it at its first array only to ask whether it is a pandas
    # object: ~0.2 s of the ~1.1 s main job)
    for heavy in ("ompl", "cv2", "numba", "qpsolvers", "proxsuite", "daqp", "scipy.spatial", "ray",
                  "rehabkit.sweep.engine", "rehabkit.hardware.backend", "pandas"):
        assert heavy not in loaded, heavy


def test_conflicting_distribution_names_both_packages(tmp_path, monkeypatch):
    site = tmp_path / "site"
    fake_dist(site, "fancy-planners", "rehabkit.planners", "multi-cubic", "fancy_planners", """\
from pydantic import BaseModel
from rehabkit import hookimpl

class Cfg(BaseModel):
    pass

@hookimpl
def rehabkit_register_planners(registry):
    registry.add("multi-cubic", config=Cfg, factory=lambda config, context: None)
""")
    r = rehabkit(site, monkeypatch, "validate", str(SCENARIOS / "hit_roundtrip.yaml"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    with pytest.raises(PluginConflictError) as twice:  # what it says: the plugin, and both packages
        registry_seeing(site, monkeypatch).get("planner", "multi-cubic")
    assert (twice.value.kind, twice.value.name) == ("planner", "multi-cubic")
    assert sorted((p.package, p.version) for p in twice.value.providers) == [("fancy-planners", "1.2.3"),
                                                                             ("rehabkit", "0.1.0")]


def test_a_sensor_whose_settings_do_not_hold_its_rate_is_refused_when_it_registers():
    """A sensor's rate is its config's ``rate_hz`` (SensorConfig), read by the run: a settings model without one
    is refused at registration, with the fix."""
    import pytest

    from rehabkit.core.plugins.types import UnknownPluginError
    from rehabkit.plugin import Sensor, StrictModel
    from tests.conftest import registry_with

    class NoRate(StrictModel):
        gain: float = 1.0

    class Probe(Sensor):
        def __init__(self, config, context):
            pass

        def read(self, t, q, qd, backend):
            return {}

    registry = registry_with("sensor", "probe", NoRate, Probe)
    (broken,) = registry.broken
    assert broken.provider.entry_point == "probe" and "sensor 'probe': its config must derive from SensorConfig" in \
        broken.error
    with pytest.raises(UnknownPluginError):
        registry.get("sensor", "probe")
