"""A user's own robot, written carelessly: a plugin's refusal is located in the file, and a run whose first
plan fails passes no expectation."""

import json

import numpy as np
import pytest

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.setup.errors import PluginSetupError, SetupError
from tests.conftest import DATA, SCENARIOS
from tests.located import located, refusal, where
from tests.test_cli import cli

ARM3 = (DATA / "arm3_dh.yaml").read_text()  # a user's own 3-joint arm, written as a DH table


def _write(tmp_path, text: str):
    path = tmp_path / "arm3.yaml"
    path.write_text(text)
    return path


def test_a_plugins_refusal_names_the_file_line_and_setting(tmp_path):
    path = _write(tmp_path, ARM3.replace("kp: [300, 300, 150]", "kp: [300, 300]"))
    with pytest.raises(PluginSetupError) as err:
        Runner(load_scenario(path)).run()
    assert isinstance(err.value, ScenarioError) and isinstance(err.value, SetupError)
    assert where(err.value) == [(18, 3, "controller.kp")]  # (its wording: tests/test_message_wording.py)
    for command in (("validate",), ("run", "--out", str(tmp_path / "out"))):  # validate finds what run refuses
        r = cli(command[0], str(path), *command[1:])
        assert (r.returncode, located(r.stderr)) == (2, [(str(path), 18, 3, "controller.kp")]), r.stderr
    # a refusal that names none of the plugin's settings points at its section
    loaded = load_scenario(path)
    fields = type(loaded.model.controller).model_fields
    (d,) = PluginSetupError(loaded.source, ("controller",), fields, "controller 'joint-pd': broke").diagnostics
    assert (d.mark.line, d.path) == (16, "controller")


def test_a_run_whose_first_plan_fails_passes_no_expectation_and_validate_refuses_it(tmp_path):
    path = _write(tmp_path, ARM3.replace("segment_durations: [2]", "segment_durations: [2, 2]"))
    r = cli("validate", str(path))  # the first plan is made (not run) by validate too
    assert (r.returncode, located(r.stderr)) == (2, [(str(path), 15, 30, "planner.segment_durations")]), r.stderr
    out = tmp_path / "out"
    r = cli("run", str(path), "--out", str(out))
    assert r.returncode == 2  # bad input, located as validate locates it; the summary says what ran
    assert located(r.stderr) == [(str(path), 15, 30, "planner.segment_durations")], r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["passed"] is False
    assert [v["passed"] for v in summary["expectations"]] == [False, False]
    # why: no plan ran, the planner's refusal stopped the robot where it stood (the verdicts' reason says so)
    assert summary["plans"] == [] and [(e["rule"], e["t"]) for e in summary["safety"]["events"]] == [("plan", 0.0)]
    verdicts = {w[1]: w[0] for w in map(str.split, r.stdout.splitlines())
                if w[:1] in (["PASS"], ["FAIL"])}  # (the report's rows)
    assert set(verdicts.values()) == {"FAIL"} and "final_joint_error_deg" in verdicts


def test_contacts_are_said_and_the_version_is_known(tmp_path):
    """An arm whose base sits on the floor (the plane z = 0) touches it the whole run: the CLI says so."""
    path = _write(tmp_path, ARM3.replace("base: {position: [0, 0, 0.5]}", "base: {position: [0, 0, 0]}"))
    r = cli("run", str(path), "--out", str(tmp_path / "out"))
    contacts = json.loads((tmp_path / "out" / "summary.json").read_text())["metrics"]["contact_steps"]
    assert contacts > 4000
    assert f"CONTACT the robot touched something in {int(contacts)} control steps (the floor is the plane z = 0)" \
        in r.stdout
    r = cli("run", str(_write(tmp_path, ARM3)), "--out", str(tmp_path / "out2"))
    verdicts = {w[1]: w[0] for w in map(str.split, r.stdout.splitlines())
                if w[:1] in (["PASS"], ["FAIL"])}
    assert r.returncode == 0 and verdicts["final_joint_error_deg"] == "PASS" and "CONTACT" not in r.stdout
    from rehabkit.core.version import __version__

    assert cli("--version").stdout.strip() == f"rehabkit {__version__}"


def test_validate_plans_an_ompl_scenario_and_exits_quietly():
    """Validating CaPaMan builds its planner and plans its first motion with OMPL (nanobind): ok, and at exit
    no binding objects are reported leaked (the CLI skips freezing the heap when OMPL is loaded)."""
    r = cli("validate", "scenarios/capaman_obstacle.yaml")
    assert r.returncode == 0 and "ok" in r.stdout
    assert "leaked" not in r.stderr


@pytest.mark.parametrize(("change", "where"), [
    (("duration: 4.5", "duration: yes"), (25, 11, "duration")),  # a number is needed here, not a boolean
    (("kd: [20, 20, 8]", "kd: [20, on, 8]"), (19, 3, "controller.kd")),
    (("duration: 4.5", "duration: .nan"), (25, 11, "duration")),  # not finite
    (("{a: 0.3}", "{a: .inf}"), (8, 11, "robot.table.1.a")),
    (("duration: 4.5", "duration: 1e9"), (25, 1, "duration")),  # 1e+12 control steps: too long to record
])
def test_validate_refuses_booleans_non_finite_numbers_and_runs_too_long_to_record(tmp_path, capsys, change, where):
    from rehabkit.cli import main

    path = _write(tmp_path, ARM3.replace(*change))
    assert main(["validate", str(path)]) == 2  # in-process: the CLI's own handling, without a process each
    line, col, at = where
    assert located(capsys.readouterr().err) == [(str(path), line, col, at)]


def test_gains_auto_tracks_where_hand_tuned_stiff_gains_shake_the_robot_into_a_stop(tmp_path):
    """The issue's own case: gains too stiff for light links in a posture where the yaw axis carries little
    inertia (the arm upright). gains: auto scales the PD by the model's inertia in every posture."""
    up = ARM3.replace("{name: B, joints_deg: [40, 60, 20]}", "{name: B, joints_deg: [-120, 80, 90]}")
    up = up.replace("{name: A, joints_deg: [0, 30, 60]}", "{name: A, joints_deg: [-60, 20, 90]}")
    stiff = Runner(load_scenario(_write(tmp_path, up))).run()
    assert not stiff.passed and stiff.metrics["safety_events"] >= 1  # a speed trip
    auto = up.replace("  kp: [300, 300, 150]\n  kd: [20, 20, 8]\n", "  gains: auto\n")
    result = Runner(load_scenario(_write(tmp_path, auto))).run()
    assert result.passed and result.metrics["safety_events"] == 0 and result.metrics["tracking_max_deg"] < 0.05


def test_gains_auto_refuses_hand_gains_and_a_bandwidth_the_control_rate_cannot_give(tmp_path):
    both = ARM3.replace("  kp: [300, 300, 150]\n", "  gains: auto\n  kp: [300, 300, 150]\n")
    done = cli("validate", str(_write(tmp_path, both)))
    assert (done.returncode, [x[1:] for x in located(done.stderr)]) == (2, [(19, 3, "controller.kp")]), done.stderr
    fast = ARM3.replace("  kp: [300, 300, 150]\n  kd: [20, 20, 8]\n", "  gains: auto\n  bandwidth_hz: 100\n")
    refused = refusal(_write(tmp_path, fast))
    assert where(refused) == [(19, 3, "controller.bandwidth_hz")]
    assert refused.diagnostics[0].fix == "at most 48"  # (the bandwidth the control rate can give)


def test_every_plugins_refusal_is_said_at_once(tmp_path):
    """A sensor's, the planner's and the controller's refusals together, each at its setting (not the first only)."""
    bad = tmp_path / "three.yaml"
    bad.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\n"
                   "sensors:\n  encoders: {type: joint-encoder, joints: [elbow_9]}\n"
                   "planner: {segment_durations: [2, 0, 2, 2]}\n"
                   "controller: {kp: [900, 900]}\n")
    with pytest.raises(ScenarioError) as err:
        Runner(load_scenario(bad)).build()
    found = {(d.path, d.mark.line) for d in err.value.diagnostics}
    assert found == {("sensors.encoders.joints", 3), ("planner.segment_durations", 4), ("controller.kp", 5)}


def test_a_plan_past_a_speed_limit_names_where_the_limit_was_set_and_what_slows_the_plan():
    """validate refuses a first plan faster than the envelope lets a joint go: at the planner (it made the plan), with
    where the limit comes from and the settings that give the plan more time."""
    refused = refusal(SCENARIOS / "hit_roundtrip.yaml", "safety.joints={wrist_1: {velocity_deg_s: 10}}")
    assert where(refused) == [(16, 3, "planner.type")]
    assert refused.diagnostics[0].fix == (
        "the limit is the safety envelope's (safety.joints.wrist_1): give the plan more time (the planner's timing "
        "settings, `rehabkit plugins --fields multi-cubic`) or the joint a higher speed limit there")


def test_an_unknown_joint_under_robot_limits_is_said_at_its_key_with_a_did_you_mean(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\nrobot:\n  type: urdf\n"
                 f"  file: {DATA / 'arm2.urdf'}\n  ee_frame: l2\n  limits:\n    j11: {{effort: 5}}\n")
    (d,) = refusal(p).diagnostics
    assert (d.mark.file, d.mark.line, d.mark.col, d.path) == (str(p), 7, 5, "robot.limits.j11")
    assert d.fix == "did you mean 'j1'? (its joints: j1, j2)"


def test_a_posture_written_in_radians_is_said_so_where_it_is_refused(tmp_path):
    """HIT's A in radians: B (A's orientation) was blamed as out of reach for its own units; a posture in radians
    that breaks a range only in degrees says so beside the limit."""
    p = tmp_path / "s.yaml"
    p.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\ntask:\n  targets:\n"
                 "    - {name: A, joints_deg: [0, 1.5708, 1.5708, 0.5236, -1.5708, 1.5708]}\n"
                 "    - {name: B, position: [-0.45, -0.1, -0.3], orientation_of: A}\n    - {name: C, same_as: A}\n"
                 "    - {name: D, same_as: B}\n    - {name: E, same_as: A}\n")
    radians = "written in radians? joints_deg takes degrees (joints_rad takes SI: radians, and metres)"
    refused = refusal(p)
    (d,) = refused.diagnostics
    assert (d.mark.file, d.mark.line, d.mark.col, d.path) == (str(p), 5, 17, "task.targets.1.position")
    # out of reach (no IK solution within the joint limits), as the planner refused it: B, for its own position
    assert (refused.__cause__.target, refused.__cause__.code) == ("B", "out-of-reach")
    assert d.fix == f"its orientation is A's, whose joint values are all within ±2π: {radians}"
    urdf = tmp_path / "knee.urdf"  # (a joint that cannot go below 0.5 rad, 28.6°)
    urdf.write_text((DATA / "arm2.urdf").read_text().replace('lower="-2" upper="2"', 'lower="0.5" upper="2"'))
    p.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\nrobot: {{type: urdf, file: {urdf}, ee_frame: l2}}\n"
                 "planner: {type: multi-cubic, segment_durations: [1.0]}\ntask:\n  targets:\n"
                 "    - {name: A, joints_deg: [45, 0]}\n    - {name: B, joints_deg: [1.2, 0.4]}\n")
    refused = refusal(p)
    (d,) = refused.diagnostics
    assert d.path == "task.targets.1.joints_deg"
    b = refused.breach  # j1 at 1.2 (degrees meant, radians taken) below its 0.5 rad
    assert (b.quantity, b.joint, b.at_s, b.value, b.limit) == ("position", "j1", 0.0, pytest.approx(np.radians(1.2)),
                                                               0.5)
    assert d.fix == f"its joint values are all within ±2π: {radians}"


def test_a_task_whose_postures_all_look_like_radians_is_said_where_they_fit_the_ranges(tmp_path, capsys):
    """Radians under joints_deg that fit the ranges are refused nowhere: the arm barely moves. validate says so at
    the posture that moves most."""
    from rehabkit.cli.main import main

    p = tmp_path / "rad.yaml"
    p.write_text(ARM3.replace("joints_deg: [0, 30, 60]", "joints_deg: [0, 0.52, 1.05]")
                 .replace("joints_deg: [40, 60, 20]", "joints_deg: [0.7, 1.05, 0.35]"))
    assert main(["validate", str(p)]) == 0
    said = capsys.readouterr().out
    assert f"PLAN    task.targets.0.joints_deg ({p}:" in said and "within ±2π (the largest 1.05): written in " \
        "radians?" in said
    p.write_text(ARM3)  # (the file as written: degrees, not said)
    assert main(["validate", str(p)]) == 0 and "radians" not in capsys.readouterr().out
