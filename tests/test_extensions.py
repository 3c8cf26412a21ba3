"""Run-lifecycle extensions: the README's example runs as written; the rehab layer is one; a broken one is named."""

from __future__ import annotations

import re
import types

import numpy as np
import pytest

from rehabkit.core.plugins.lifecycle import Extensions
from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.setup.errors import SetupError
from tests.conftest import ROOT, SCENARIOS

SHORT = {"duration": 2.5, "planner.segment_durations": [1, 1], "task.sequence": ["A", "B", "A"], "expect": None}


def _readme_extension() -> types.ModuleType:
    """The README's extension example, executed as a module."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```python\n(# my_lab/fast_moves.py.*?)```", text, re.S).group(1)
    module = types.ModuleType("fast_moves")
    exec(compile(block, "README.md:fast_moves", "exec"), module.__dict__)
    return module


def test_the_readme_extension_adds_its_metric_to_every_run():
    from rehabkit.rehab import extension as rehab

    exts = Extensions([("rehab", rehab), ("fast-moves", _readme_extension())], entry_points=False)
    loaded = load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT, extensions=exts)
    assert loaded.model.fast_moves.share == 0.2  # the section's default, where the scenario leaves it out
    result = Runner(loaded, extensions=exts).run()
    metrics = result.summary["metrics"]
    assert result.summary["metric_info"]["fast_time_s"]["unit"] == "s"
    # each description is its every field but the name (written out for speed: a field added is a field listed)
    from dataclasses import asdict

    fast = next(m for m in exts.metrics() if m.name == "fast_time_s")
    assert result.summary["metric_info"]["fast_time_s"] == {k: v for k, v in asdict(fast).items() if k != "name"}
    # recomputed from the trace: the time steps any joint exceeded a fifth of its speed limit
    from rehabkit_plugins.robots.hit import HitConfig, HitRobot

    vmax = HitRobot(HitConfig()).model.limits.velocity
    expected = np.count_nonzero((np.abs(result.trace.qd) > 0.2 * vmax).any(axis=1)) * 1e-3
    assert metrics["fast_time_s"] == pytest.approx(expected) and expected > 0.1
    assert "sparc" in metrics  # the rehab layer's measures alongside


def test_a_layers_own_section_is_validated_located_and_in_the_schema(tmp_path):
    """The README's extension owns ``fast_moves:``: its value sets the metric, a bad one is refused at its line and
    column with the layer's own words, a misspelt section name gets the nearest, and the schema has it."""
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.models import scenario_model

    exts = Extensions([("fast-moves", _readme_extension())], entry_points=False)
    stricter = load_scenario(SCENARIOS / "hit_roundtrip.yaml", {**SHORT, "fast_moves.share": 0.5}, extensions=exts)
    wider = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT, extensions=exts), extensions=exts).run()
    assert Runner(stricter, extensions=exts).run().metrics["fast_time_s"] < wider.metrics["fast_time_s"]
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\nfast_moves:\n  share: 3\nfast_move: {{}}\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(bad, extensions=exts)
    found = {(d.path, d.mark.line, d.mark.col): d for d in err.value.diagnostics}
    assert "less than or equal to 1" in found[("fast_moves.share", 3, 10)].message
    assert found[("fast_move", 4, 1)].fix.startswith("did you mean 'fast_moves'")
    schema = scenario_model(default_registry(), exts).model_json_schema()
    assert schema["properties"]["fast_moves"]["description"] == "what counts as a fast move"


def test_without_the_rehab_extension_a_run_has_no_outcome_measures_and_the_core_still_runs():
    exts = Extensions(entry_points=False)
    result = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT), extensions=exts).run()
    assert result.metrics["final_position_error_m"] < 0.005
    assert "sparc" not in result.metrics and "patient" not in result.summary


def test_a_broken_extension_stops_runs_naming_it():
    broken = types.ModuleType("broken")
    exec("from rehabkit.plugin import hookimpl\n\n@hookimpl\ndef rehabkit_run_finishd(setup, record):\n    pass\n",
         broken.__dict__)  # a misspelt hook: pluggy refuses it
    exts = Extensions([("typo-layer", broken)], entry_points=False)
    with pytest.raises(SetupError):
        Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT), extensions=exts).build()
    assert [b.name for b in exts.broken] == ["typo-layer"]


def test_each_hook_is_given_what_it_reads_and_the_core_applies_what_it_returns():
    """No hook is given the run's assembly: each reads narrow, read-only arguments and returns what it adds — other
    robot settings (their notes kept for it), a replaced target, a tap — which the core applies; the extension's
    notes and tap come back to it as its ``state`` at the run's end."""
    from dataclasses import FrozenInstanceError, replace

    from rehabkit.core.plugins.lifecycle import Admission, ExtensionState, RobotSettings, RunInfo
    from rehabkit.plugin import Contribution, RunTap, hookimpl

    seen: dict = {}

    class Tap(RunTap):
        readings = 0

        def reading(self, t, name, reading):
            self.readings += 1

    layer = types.ModuleType("typed_layer")

    @hookimpl
    def rehabkit_configure_robot(robot_config):
        return RobotSettings(robot_config.model_copy(), {"why": "a copy"})

    @hookimpl
    def rehabkit_narrow_limits(model):
        seen["dof"] = model.dof
        return []

    @hookimpl
    def rehabkit_force_limit(scenario):
        seen["scenario"] = scenario
        return None  # (a limit needs a source of the force: the round trip measures none)

    @hookimpl
    def rehabkit_admit_targets(targets):
        seen["targets"] = targets
        return Admission({"B": replace(targets["B"])}, ({"target": "B", "why": "a copy"},))

    @hookimpl
    def rehabkit_run_opened(run, state):
        seen["opened"] = run, state
        return Tap()

    @hookimpl
    def rehabkit_run_finished(run, record, state):
        seen["finished"] = run, state
        return Contribution(sections={"typed": {"notes": dict(state.notes), "readings": state.tap.readings > 0}})

    for hook in (rehabkit_configure_robot, rehabkit_narrow_limits, rehabkit_force_limit, rehabkit_admit_targets,
                 rehabkit_run_opened, rehabkit_run_finished):
        setattr(layer, hook.__name__, hook)
    exts = Extensions([("typed", layer)], entry_points=False)
    runner = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT, extensions=exts), extensions=exts)
    result = runner.run()
    a = runner.setup
    assert seen["dof"] == a.robot.model.dof and a.robot_config is not a.sc.robot
    with pytest.raises(TypeError):  # (the targets are read, not written)
        seen["targets"]["A"] = None
    assert a.targets["B"] is not seen["targets"]["B"] and a.replaced == [{"target": "B", "why": "a copy"}]
    run, opened = seen["opened"]
    assert isinstance(run, RunInfo) and opened == ExtensionState({"why": "a copy"})
    assert run.replaced == tuple(a.replaced) and run.targets["B"] is a.targets["B"]
    with pytest.raises(FrozenInstanceError):
        run.robot = None
    _, finished = seen["finished"]
    assert isinstance(finished.tap, Tap) and exts.state(a, "typed").tap is None  # (the tap was the run's)
    assert result.summary["typed"] == {"notes": {"why": "a copy"}, "readings": True}
    assert seen["scenario"] is a.sc and run.scenario is a.sc and a.safety.config.interaction_force_n is None
