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
    found = {(d.path, d.mark.line, d.mark.col): d.message for d in err.value.diagnostics}
    assert "less than or equal to 1" in found[("fast_moves.share", 3, 10)]
    assert "did you mean 'fast_moves'" in found[("fast_move", 4, 1)]
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
    with pytest.raises(SetupError, match="extension 'typo-layer' failed to load: .*rehabkit_run_finishd"):
        Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", SHORT), extensions=exts).build()
