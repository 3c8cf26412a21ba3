"""Range-of-motion assessment (rehabkit assess): the simulated person's own ranges recovered, a new version of
their profile written, and that version narrowing the next session's limits."""

from __future__ import annotations

import json
import math

import pytest
import yaml

from rehabkit.cli import main
from rehabkit.core.plugins.lifecycle import default_extensions
from rehabkit.core.plugins.registry import default_registry
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.setup.assembly import assemble
from tests.conftest import SCENARIOS

PATIENT = SCENARIOS / "lexos_patient.yaml"


def test_an_assessment_recovers_the_persons_ranges_and_narrows_the_next_session(tmp_path, capsys):
    truth = yaml.safe_load((SCENARIOS / "patients" / "p01.yaml").read_text())["joints"]
    # the README's command, on two joints of four (benchmarks/rom_assessment.py: all of them)
    assert main(["assess", str(PATIENT), "--out", str(tmp_path / "rom"), "--joints", "q2_flexion,q4_elbow"]) == 0
    assert "wrote" in capsys.readouterr().out
    report = json.loads((tmp_path / "rom" / "assessment.json").read_text())
    for joint, rom in truth.items():  # the spring-damper person: its profile's ranges, within 2°
        if joint not in report["active_deg"]:
            continue
        for kind in ("active", "passive"):
            measured, true = report[f"{kind}_deg"][joint], rom[f"{kind}_deg"]
            assert max(abs(measured[0] - true[0]), abs(measured[1] - true[1])) < 2.0, (joint, kind, measured, true)
    assert set(report["active_deg"]) == {"q2_flexion", "q4_elbow"}
    assert report["passive_stopped_by"]["q2_flexion"] == ["end-feel", "end-feel"]  # (the elbow's: the robot's too)
    new = tmp_path / "rom" / "P01.v2.yaml"
    profile = yaml.safe_load(new.read_text())
    assert profile["version"] == 2 and profile["assessed"]["date"] and profile["id"] == "P01"
    # the next session's limits are the measured passive ranges
    loaded = load_scenario(PATIENT, {"patient": str(new)})
    a = assemble(loaded, default_registry(), default_extensions(), upto="targets")
    j = a.robot.model.joint_names.index("q2_flexion")
    assert math.degrees(a.limits.upper[j]) == profile["joints"]["q2_flexion"]["passive_deg"][1]
    assert a.limit_sources.by_joint["q2_flexion"]["upper"][0] == "patient"


def test_an_assessment_needs_a_person(capsys):
    from rehabkit.core.setup.errors import SetupError
    from rehabkit.rehab.assess import assess

    assert main(["assess", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", "/nonexistent/x"]) == 1
    with pytest.raises(SetupError) as refused:  # (what the command refused with: HIT's scenario has no patient)
        assess(SCENARIOS / "hit_roundtrip.yaml", "/nonexistent/x")
    assert refused.value.setting == ("patient",)


def test_a_session_the_envelope_stops_leaves_the_rest_measured_and_the_profile_as_it_was(tmp_path, capsys):
    # a comfort force so low the first stretch presses past it: the stretch ends itself at 80 % of it (a force cap)
    low = ["--set", "patient.comfort.max_interaction_force_n=6", "--joints", "q2_flexion,q4_elbow"]
    assert main(["assess", str(PATIENT), "--out", str(tmp_path / "capped"), *low]) == 1  # (the active session trips)
    capped = json.loads((tmp_path / "capped" / "assessment.json").read_text())
    assert "force cap" in capped["passive_stopped_by"]["q2_flexion"] and "passive" not in capped["sessions_stopped"]
    # told to press harder than the envelope allows, the stretch is cut short by the safety stop: a bound, not an end
    assert main(["assess", str(PATIENT), "--out", str(tmp_path / "rom"), *low, "--stretch", "max_force_n=50"]) == 1
    assert "session was stopped" in capsys.readouterr().out
    report = json.loads((tmp_path / "rom" / "assessment.json").read_text())
    assert "passive" in report["sessions_stopped"]
    whys = [w for ends in report["passive_stopped_by"].values() for w in ends]
    assert "safety stop: interaction-force" in whys and None in whys  # cut short, then nothing more
    previous = yaml.safe_load((SCENARIOS / "patients" / "p01.yaml").read_text())["joints"]["q4_elbow"]
    written = yaml.safe_load((tmp_path / "rom" / "P01.v2.yaml").read_text())["joints"]["q4_elbow"]
    assert written["passive_deg"] == previous["passive_deg"]  # not measured: kept as it was
