"""The patient profile: effective limits, targets refused or replaced, segment lengths, profile files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from rehabkit.api import run_scenario
from rehabkit.cli import main
from rehabkit.core.run.runner import Runner, SetupError
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.scenario.safety import SafetyConfig
from rehabkit.rehab.patient import PatientBase, effective_limits
from tests.conftest import SCENARIOS
from tests.located import located, where

HIT = SCENARIOS / "hit_roundtrip.yaml"


def _scenario(tmp_path, patient, name="s.yaml", **extra):
    """The HIT round trip with a patient section (a mapping, or a profile file name)."""
    data = {"extends": str(HIT), "patient": patient, "duration": 8.5, **extra}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_effective_limits_are_the_tighter_of_robot_patient_and_envelope(hit):
    lim = hit.model.limits
    patient = PatientBase.model_validate({
        "id": "T1", "side": "right",
        "joints": {"elbow_1": {"passive_deg": [60, 100], "max_speed_deg_s": 30},
                   "shoulder_1": {"passive_deg": [-400, 400]}},  # wider than the robot: the robot's hold
        "comfort": {"max_speed_deg_s": 45}})
    safety = SafetyConfig.model_validate({"joints": {"elbow_1": {"range_deg": [70, 120]},
                                                     "wrist_2": {"torque_nm": 0.5}}})
    eff, src = effective_limits(hit.model, patient, safety)
    j = hit.model.joint_names.index("elbow_1")
    assert eff.lower[j] == pytest.approx(math.radians(70)) and eff.upper[j] == pytest.approx(math.radians(100))
    assert eff.velocity[j] == pytest.approx(math.radians(30))
    assert src.by_joint["elbow_1"]["lower"][0] == "safety" and src.by_joint["elbow_1"]["upper"][0] == "patient"
    s1 = hit.model.joint_names.index("shoulder_1")
    assert eff.lower[s1] == lim.lower[s1] and eff.upper[s1] == lim.upper[s1]
    assert eff.velocity[s1] == pytest.approx(min(lim.velocity[s1], math.radians(45)))
    w2 = hit.model.joint_names.index("wrist_2")
    assert eff.effort[w2] == 0.5


def test_a_joint_target_outside_the_patients_range_is_refused_with_its_place(tmp_path, capsys):
    # target A puts elbow_1 at 90°; this patient's elbow goes no further than 80°
    path = _scenario(tmp_path, {"id": "P9", "side": "right", "joints": {"elbow_1": {"passive_deg": [20, 80]}}})
    with pytest.raises(ScenarioError) as err:
        run_scenario(path)
    (d,) = err.value.diagnostics  # at target A (line 30 of the file it extends), which breaks elbow_1's range
    assert (Path(d.mark.file).name, d.mark.line, d.mark.col, d.path) == (HIT.name, 30, 7, "task.targets.0")
    assert d.fix == "move the target into the range, or set patient.outside_rom: nearest to use the nearest " \
        "admissible point"
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2
    assert [x[1:] for x in located(capsys.readouterr().err)] == [(30, 7, "task.targets.0")]
    assert not (tmp_path / "o" / "summary.json").exists()  # refused before it runs: nothing written


def test_a_cartesian_target_whose_posture_leaves_the_range_is_refused(tmp_path):
    # B (Cartesian) needs shoulder_2 well below 90°; A sits at 90°, so a range [85, 120]° admits A only
    path = _scenario(tmp_path, {"id": "P9", "side": "right", "joints": {"shoulder_2": {"passive_deg": [85, 120]}}})
    with pytest.raises(ScenarioError) as err:
        run_scenario(path)
    assert where(err.value) == [(31, 7, "task.targets.1")]  # B only, not A


def test_nearest_admissible_target_replaces_it_and_the_run_stays_in_range(tmp_path, hit):
    path = _scenario(tmp_path, {"id": "P9", "side": "right", "outside_rom": "nearest",
                                "joints": {"elbow_1": {"passive_deg": [20, 80]}}})
    result = run_scenario(path, out_dir=tmp_path / "out")
    replaced = result.summary["patient"]["replaced_targets"]
    assert [r["target"] for r in replaced] == ["A"] and replaced[0]["joints"] == ["elbow_1"]
    assert replaced[0]["to_deg"][2] == pytest.approx(80.0)
    j = hit.model.joint_names.index("elbow_1")
    assert np.degrees(result.trace.q[:, j]).max() < 80.0 + 0.5  # the arm never goes past the patient's range
    assert result.metrics["final_position_error_m"] < 0.005  # and still reaches the (replaced) goal
    assert result.summary["safety"]["events"] == []


def test_unknown_joint_names_are_located_with_suggestions(tmp_path):
    path = _scenario(tmp_path, {"id": "P9", "side": "right", "joints": {"elbow1": {"passive_deg": [20, 80]}}},
                     safety={"joints": {"wrist2": {"torque_nm": 1}}})
    with pytest.raises(ScenarioError) as err:
        Runner(load_scenario(path)).build()
    assert where(err.value) == [(6, 5, "patient.joints.elbow1"), (13, 5, "safety.joints.wrist2")]
    assert {Path(d.mark.file).name for d in err.value.diagnostics} == {"s.yaml"}
    elbow, wrist = err.value.diagnostics
    assert (elbow.fix, wrist.fix) == ("did you mean 'elbow_1' or 'elbow_2'?", "did you mean 'wrist_2' or 'wrist_1'?")


def test_profile_in_its_own_file_errors_point_into_it(tmp_path):
    (tmp_path / "p.yaml").write_text("id: P1\nside: rigth\njoints:\n  elbow_1: {passive_deg: [90, 20]}\n")
    path = _scenario(tmp_path, "p.yaml")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert where(err.value) == [(2, 7, "patient.side"), (4, 3, "patient.joints.elbow_1")]
    assert {Path(d.mark.file).name for d in err.value.diagnostics} == {"p.yaml"}


def test_profile_ids_are_pseudonyms_not_names(tmp_path):
    path = _scenario(tmp_path, {"id": "Jane Doe", "side": "left"})
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert where(err.value) == [(3, 7, "patient.id")]


def test_the_lexos_adapts_its_segments_to_the_profile_unless_the_scenario_sets_them(tmp_path):
    base = {"robot": {"type": "lexos", "upper_arm": 0.31}, "planner": {"type": "multi-cubic", "segment_durations": [1]},
            "controller": {"type": "joint-pd"},
            "task": {"targets": [{"name": "a", "joints_deg": [20, -45, 0, -70]},
                                 {"name": "b", "joints_deg": [25, -40, 0, -60]}]},
            "duration": 1.0, "patient": {"id": "P2", "side": "right",
                                         "segments": {"upper_arm": 0.28, "forearm": 0.31, "hand": 0.1}}}
    path = tmp_path / "lexos.yaml"
    path.write_text(yaml.safe_dump(base))
    run = Runner(load_scenario(path))
    run.build()
    assert run.robot.lengths == (0.31, 0.31)  # upper_arm set in the scenario wins; forearm from the profile
    # what the rehab extension noted when it set the robot up (its ExtensionState), as summary.json's patient.segments
    segments = run.setup.extensions.state(run.setup, "rehab").notes["segments"]
    assert "from the profile" in segments["forearm"] and "set in the scenario" in segments["upper_arm"]
    assert "no setting 'hand'" in segments["hand"]


def test_a_plan_faster_than_the_patients_comfort_is_refused_before_it_runs(tmp_path):
    # the round trip's 2 s segments turn the wrist at ~35 °/s; this person is comfortable with 20 °/s
    path = _scenario(tmp_path, {"id": "P9", "side": "right", "comfort": {"max_speed_deg_s": 20}})
    with pytest.raises(SetupError) as err:
        run_scenario(path, out_dir=tmp_path / "o")
    breach = err.value.breach  # what the message says, as fields
    assert (breach.quantity, breach.joint, breach.at_s) == ("velocity", "wrist_1", pytest.approx(0.25))
    assert breach.limit == pytest.approx(np.radians(20.0)) and breach.value > breach.limit
    assert not (tmp_path / "o" / "summary.json").exists()
    slower = run_scenario(path, {"planner.segment_durations": [5, 5, 5, 5], "duration": 20.5})
    assert slower.summary["safety"]["events"] == [] and slower.metrics["final_position_error_m"] < 0.005
