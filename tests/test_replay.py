"""Counterfactual replay: the L-Exos session with a simulated patient, joint PD against assist-as-needed."""

from __future__ import annotations

import json

import pytest
import yaml
from rerun.chunk import RrdReader

from rehabkit.api import run_scenario
from rehabkit.cli import main
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.rehab.replay import replay
from tests.conftest import SCENARIOS

# the first reach of the session, to keep the test short: the ball shown at Target 1 at 0.5 s (the soft start's end)
# rather than 4 s, and the 5.6 s after it the session's 9.6 s gave it (the 3.5 s before it are the arm held still, the
# camera seeing nothing: as simulated, rendered and recorded as the reach, twice over, for the run and its replay)
FIRST_REACH = ["duration=6.1", "task.events.0.at=0.5"]


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("lexos_patient")
    result = run_scenario(SCENARIOS / "lexos_patient.yaml", FIRST_REACH, out_dir=out)
    return out, result


def test_a_run_keeps_the_scenario_as_it_ran(session):
    out, result = session
    snap = yaml.safe_load((out / "scenario.yaml").read_text())
    assert snap["duration"] == 6.1 and snap["task"]["events"][0]["at"] == 0.5  # --set applied
    assert snap["patient"]["id"] == "P01"  # profile inlined
    assert "extends" not in snap and snap["controller"]["type"] == "clik-pd"
    assert result.summary["inputs"]["patient_noise"]


def test_replay_with_assist_as_needed_same_inputs_less_assistance(session, tmp_path):
    out, pd = session
    rep = replay(out, ["controller.type=assist-as-needed"], tmp_path / "aan")
    aan = rep.result
    assert all(rep.same_inputs.values()), rep.same_inputs  # same seed, target timeline, patient and sensor noise
    assert aan.summary["plugins"]["controller"]["type"] == "assist-as-needed"
    assert aan.summary["patient"]["simulated"] == "simulated-arm"
    a, b = pd.metrics, aan.metrics
    assert a["reaches"] == b["reaches"] == 1 and a["reaches_completed"] == b["reaches_completed"] == 1
    # the robot gives way: it does less of the work, the person more, and presses on the person less
    assert b["assistance_ratio"] < a["assistance_ratio"]
    assert b["patient_voluntary_work_j"] > a["patient_voluntary_work_j"]
    assert b["peak_interaction_force_n"] < a["peak_interaction_force_n"]
    table = rep.table()
    assert "clik-pd / voxel-beam" in table and "assist-as-needed / voxel-beam" in table
    assert "assistance_ratio" in table and "inputs: seed same" in table
    saved = json.loads((tmp_path / "aan" / "summary.json").read_text())
    assert saved["metrics"]["assistance_ratio"] == pytest.approx(b["assistance_ratio"])
    # the measures and the person's and the controller's states are in the Rerun recording too (read by Rerun's own
    # reader, in this process: `rerun rrd print` was a process of its own for the same listing)
    entities = {str(chunk.entity_path) for chunk in RrdReader(str(tmp_path / "aan" / "run.rrd")).stream().to_chunks()}
    for entity in ("/outcomes/sparc", "/outcomes/path_length_ratio", "/outcomes/time_to_target_s",
                   "/outcomes/interaction_force_n", "/patient/capacity", "/controller/assist_stiffness", "/events"):
        assert entity in entities, entity


def test_replay_needs_a_run_directory(tmp_path, capsys):
    with pytest.raises(ScenarioError) as refused:
        replay(tmp_path)
    assert [(d.mark.file, d.mark.line, d.path) for d in refused.value.diagnostics] == [(str(tmp_path), 0, "")]
    assert main(["replay", str(tmp_path)]) == 2
    assert capsys.readouterr().err.splitlines() == [str(d) for d in refused.value.diagnostics]  # (said at the folder)
