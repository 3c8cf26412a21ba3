"""The README's guide to writing plugins runs as written: its package, entry points, scenario, test and robot."""

import re

import numpy as np
import pytest

from rehabkit.core.scenario.errors import ScenarioError
from tests.conftest import ROOT, SCENARIOS
from tests.test_readme import BLOCKS, README


def test_the_plugin_snippet_is_the_example_plugins_registration():
    snippet = next(b for lang, b in BLOCKS if lang == "python" and "rehabkit_register_planners" in b)
    source = (ROOT / "examples" / "third_party_plugin" / "rehabkit_minjerk" / "__init__.py").read_text()
    assert 'registry.add("min-jerk", config=MinJerkConfig, factory=MinJerkPlanner)' in snippet
    assert 'registry.add("min-jerk", config=MinJerkConfig, factory=MinJerkPlanner)' in source


def test_the_plugin_guide_runs_as_written(tmp_path, capsys):
    """The guide's package (a sensor and a controller reading it by name), its entry points, its scenario and its
    test, as a third party writes them: registered as the entry points name them, run, refused where it says."""
    import tomllib
    import types

    from rehabkit.api import run_scenario
    from rehabkit.cli.plugin_reference import plugin_reference
    from rehabkit.core.plugins.registry import Provider, load_plugins
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    guide = README[README.index("### Writing a plugin"):]
    code = re.search(r"```python\n(# mylab/plugins.py\n.*?)```", guide, re.S).group(1)
    module = types.ModuleType("mylab.plugins")
    exec(compile(code, "README.md (mylab/plugins.py)", "exec"), module.__dict__)
    points = tomllib.loads(re.search(r"```toml\n(.*?)```", guide, re.S).group(1))["project"]["entry-points"]
    assert points == {"rehabkit.sensors": {"noisy-angles": "mylab.plugins"},
                      "rehabkit.controllers": {"sensed-pd": "mylab.plugins"}}
    registry = load_plugins(extra=[(module, Provider("mylab", "0.1", "mylab.plugins"))])
    assert {"noisy-angles", "sensed-pd"} <= set(registry.names("sensor")) | set(registry.names("controller"))
    fields = plugin_reference(registry.get("controller", "sensed-pd"))  # `rehabkit plugins --fields sensed-pd`
    assert "controller 'sensed-pd' (mylab 0.1)" in fields and "sensor: SensorName = required" in fields
    scenario = tmp_path / "sensed_roundtrip.yaml"
    text = re.search(r"```yaml\n(# sensed_roundtrip.yaml.*?)```", guide, re.S).group(1)
    scenario.write_text(text.replace("extends: hit_roundtrip.yaml", f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}"))
    result = run_scenario(scenario, registry=registry, out_dir=tmp_path / "out")
    assert result.passed and result.metrics["safety_events"] == 0
    from tests.test_recording_layout import recording

    names = recording(tmp_path / "out" / "run.rrd")["sensors/angles/angles"]["SeriesLines:names"][0]
    assert names == [f"{j} angles" for j in result.summary["per_joint"]]
    assert 0.04 < result.metrics["angle_noise_rms_deg"] < 0.06 and result.metrics["tracking_rms_deg"] < 0.6
    for wrong, where, said, fix in (("sensor: angles", "controller.sensor", "no sensor 'angle' in this scenario",
                                     "did you mean 'angles'? (its sensors: encoders, angles)"),
                                    ("kp: [900, 900, 150, 180, 16, 18]", "controller.kp",
                                     "give one gain or 6, one per joint", "")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(scenario.read_text().replace(wrong, "sensor: angle" if "sensor" in wrong else "kp: [900, 900]"))
        with pytest.raises(ScenarioError) as err:
            Runner(load_scenario(bad, registry=registry), registry=registry).build()  # (what `validate` does)
        (d,) = err.value.diagnostics
        assert d.path == where and said in d.message and d.fix == fix, d
    test = re.search(r"```python\n(import pytest\n\n@pytest.mark.parametrize\(\"noise_deg\".*?)```", guide,
                     re.S).group(1)
    scope: dict = {}
    exec(compile(test, "README.md (the guide's test)", "exec"), scope)

    def fixture(path, **kw):  # the run_scenario fixture, with this registry in place of the installed plugins
        return run_scenario(scenario if path == "sensed_roundtrip.yaml" else path,
                            {k.replace("__", "."): v for k, v in kw.items()}, registry=registry)

    for noise in (0.0, 0.2):
        scope["test_the_pd_tracks_through_the_noise"](fixture, noise)


def test_the_plugin_table_lists_every_built_in_plugin():
    """The README's table of plugins against the registry: every plugin rehabkit installs, and none it doesn't."""
    from rehabkit.core.plugins.registry import default_registry

    registry = default_registry()
    registry.load_all()
    table = README[README.index("| kind | name | |"):README.index("Two installable packages")]
    listed = {(cells[0], name) for row in table.splitlines()[2:]
              if len(cells := [c.strip() for c in row.strip("|").split("|")]) >= 2
              for name in re.findall(r"`([^`]+)`", cells[1])}
    installed = {(kind, name) for kind in ("robot", "planner", "controller", "sensor", "backend", "patient")
                 for name in registry.names(kind) if registry.get(kind, name).provider.package == "rehabkit"}
    assert listed == installed


def test_the_guides_robot_is_a_robot():
    """The guide's whole robot, as written: its model loads in MuJoCo and Pinocchio, its hand where its links say."""
    code = re.search(r"```python\n(import numpy as np\n\nfrom rehabkit.plugin import Context, JointLimits.*?)```",
                     README, re.S).group(1)
    scope: dict = {}
    exec(compile(code, "README.md (the guide's robot)", "exec"), scope)
    robot = scope["TwoLink"](scope["TwoLinkConfig"](), None)
    np.testing.assert_allclose(robot.fk(np.zeros(2))[:3, 3], [0.55, 0, 0], atol=1e-12)
    np.testing.assert_allclose(robot.ee_world(np.zeros((1, 2)))[0], [0.55, 0, 1.0], atol=1e-12)
    np.testing.assert_allclose(robot.fk(np.array([np.pi / 2, 0]))[:3, 3], [0, 0, 0.55], atol=1e-12)  # up: y axis −1
    assert robot.jacobian(np.zeros(2)).shape == (6, 2) and robot.mass_matrix(np.zeros(2))[0, 0] > 0
