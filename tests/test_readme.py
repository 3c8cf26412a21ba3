"""The README runs: each of its code blocks and each command it names is executed here or, where a run is long,
by the test named for it below (checked to exist)."""

import csv
import json
import re
import shlex
from pathlib import Path

import numpy as np
import yaml

from tests.conftest import ROOT
from tests.test_cli import cli

README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```(\w*)\n(.*?)```", README, re.S)

# commands the README names whose runs other tests make (long ones): command -> test file :: test function
EXECUTED_ELSEWHERE = {
    "rehabkit replay out/lexos_patient --set controller.type=assist-as-needed":
        "tests/test_replay.py::test_replay_with_assist_as_needed_same_inputs_less_assistance",
    "rehabkit sweep scenarios/lexos_planner_trial.yaml":
        "tests/test_sweep.py::test_serial_and_ray_give_the_same_rows_and_a_second_call_runs_nothing",
    "rehabkit run scenarios/lexos_reaching.yaml --set backend.type=hardware":
        "tests/test_hardware_link.py::test_lexos_reaching_over_the_link_reaches_the_proxy_points_of_the_simulation",
    "rehabkit plugins": "tests/test_cli.py::test_plugins_and_schema_commands",
    # the plugin guide's, for its own package: run in-process with its registry (it is not installed here)
    "rehabkit plugins --fields sensed-pd": "tests/test_readme_plugins.py::test_the_plugin_guide_runs_as_written",
    "rehabkit validate sensed_roundtrip.yaml": "tests/test_readme_plugins.py::test_the_plugin_guide_runs_as_written",
    "rehabkit bridge --help": "tests/test_readme.py::test_every_option_of_every_command_is_in_the_readme",
    "rehabkit plugins --json": "tests/test_cli.py::test_plugins_and_schema_commands",
    "rehabkit schema": "tests/test_cli.py::test_plugins_and_schema_commands",
    "rehabkit schema > rehabkit.schema.json": "tests/test_cli.py::test_plugins_and_schema_commands",
    "rehabkit --version": "tests/test_user_robot_errors.py::test_contacts_are_said_and_the_version_is_known",
    "rehabkit assess scenarios/lexos_patient.yaml --out out/rom":
        "tests/test_assessment.py::test_an_assessment_recovers_the_persons_ranges_and_narrows_the_next_session",
    "rehabkit safety-report":
        "tests/test_safety_report.py::test_the_report_gives_every_skill_in_simulation_over_the_link_and_on_canopen",
    "rehabkit estop list": "tests/test_stops.py::test_an_estop_stays_latched_across_runs_until_a_person_clears_it",
    'rehabkit estop clear sim-hit --by "J. Doe"':
        "tests/test_stops.py::test_an_estop_stays_latched_across_runs_until_a_person_clears_it",
    "rehabkit plugins --fields musculoskeletal":
        "tests/test_cli.py::test_a_plugins_reference_gives_every_setting_with_units_and_defaults_and_its_metrics",
    "rehabkit keys new hit-1 --out keys/hit-1.key --replace":
        "tests/test_link_security.py::test_the_readmes_lab_network_commands_run_as_written",
    "rehabkit drives": "tests/test_canopen_readme.py::test_simulated_drives_in_another_process_as_the_readme_runs_them",
    "rehabkit plugins --fields recorded-wrench":
        "tests/test_bag_replay.py::test_bags_that_do_not_fit_are_said_at_the_bag",
    "rehabkit plugins --fields dh":
        "tests/test_cli.py::test_a_plugins_reference_gives_every_setting_with_units_and_defaults_and_its_metrics",
    # the study section's block runs there line by line (short sessions), and these two with it
    "rehabkit export bids":
        "tests/test_bids_export.py::test_the_study_dataset_passes_the_validator_with_no_error_and_no_warning",
    "rehabkit progress": "tests/test_bids_export.py::test_the_progress_page_draws_and_says_each_change",
}
MUSCLES = "tests/test_readme.py::test_the_musculoskeletal_commands_compare_controllers_and_severities"
_MUSCLE_BLOCK = re.search(r"## A musculoskeletal patient.*?```bash\n(.*?)```", README, re.S)[1]
_POLICY_REPLAY = re.search(r"## Learning: scenarios.*?```bash\n(.*?)```", README, re.S)[1].strip()
EXECUTED_ELSEWHERE.update({c.split("#")[0].strip(): MUSCLES for c in [*_MUSCLE_BLOCK.splitlines(), _POLICY_REPLAY]})


def _block_after(marker: str, lang: str) -> str:
    tail = README[README.index(marker):]
    return re.search(rf"```{lang}\n(.*?)```", tail, re.S).group(1)


def _run(command: str, tmp_path, cwd=ROOT):
    """A README command line, its ``--out`` sent to ``tmp_path`` (the README's own goes under the repository)."""
    args = shlex.split(command.split("#")[0])
    assert args[0] == "rehabkit"
    if "--out" in args:
        args[args.index("--out") + 1] = str(tmp_path / args[args.index("--out") + 1].replace("/", "_"))
    return cli(*args[1:], cwd=cwd), args


def test_the_main_job_is_what_the_cli_test_runs():
    """The first lines: set-up and the main job, set-up and the tests. tests/test_cli.py runs the main job's
    command (its scenario, writing run.rrd and summary.json, exit 0)."""
    lang, block = BLOCKS[0]
    assert lang == "bash"
    main, tests = block.strip().splitlines()
    assert main.split("#")[0].split() == ["pip", "install", "-e", '".[dev]"', "&&", "rehabkit", "run",
                                          "scenarios/hit_roundtrip.yaml", "--out", "out/hit"]
    assert tests.split("#")[0].split()[-3:] == ["python", "-m", "pytest"]
    cli_test = (ROOT / "tests" / "test_cli.py").read_text()
    assert 'cli("run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(tmp_path))' in cli_test


def test_the_bad_file_gives_exactly_the_errors_shown(tmp_path):
    (tmp_path / "bad.yaml").write_text(_block_after("For this `bad.yaml`", "yaml"))
    shown = _block_after("`rehabkit validate bad.yaml` prints", "").strip().splitlines()
    done = cli("validate", "bad.yaml", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == shown


def test_the_scenario_example_runs_and_replans_from_where_the_arm_is(tmp_path):
    text = _block_after("## Scenarios", "yaml")
    path = tmp_path / "example.yaml"
    path.write_text(text)
    assert cli("validate", str(path)).returncode == 0
    done = cli("run", str(path), "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    first, again = summary["plans"]
    assert first["t"] == 0 and 2.0 < again["t"] < 3.5  # when the hand came within 5 mm of B
    # the second plan leaves from where the arm was (near B, not back at A) and goes to C (= A) only
    a = np.array(yaml.safe_load(text)["task"]["targets"][0]["joints_deg"])
    start, end = np.array(again["waypoints_deg"][0]), np.array(again["waypoints_deg"][-1])
    assert len(again["waypoints_deg"]) == 2 and np.abs(start - a).max() > 20 and np.abs(end - a).max() < 1e-6
    assert summary["metrics"]["safety_events"] == 0 and summary["metrics"]["tracking_max_deg"] < 0.5
    assert "SAFETY" not in done.stdout


def test_the_safety_section_is_valid_on_a_robot_with_a_simulated_patient(tmp_path):
    envelope = yaml.safe_load(_block_after("declarative envelope on top of the robot's limits", "yaml"))
    path = tmp_path / "enveloped.yaml"
    (tmp_path / "patients").mkdir()  # the base file's relative patient path resolves from the extending file
    (tmp_path / "patients" / "p01.yaml").write_text((ROOT / "scenarios" / "patients" / "p01.yaml").read_text())
    path.write_text(f"extends: {ROOT / 'scenarios' / 'lexos_patient.yaml'}\n" + yaml.safe_dump(envelope))
    done = cli("validate", str(path))
    assert done.returncode == 0, done.stderr


def test_your_own_robot_commands_run(tmp_path):
    block = _block_after("## Your own robot", "bash")
    for line in block.strip().splitlines():
        done, args = _run(line, tmp_path)
        assert done.returncode == 0, (line, done.stdout, done.stderr)
        if args[1] == "run":
            verdicts = {w[1]: w[0] for w in map(str.split, done.stdout.splitlines())
                        if w[:1] in (["PASS"], ["FAIL"])}
            assert verdicts and set(verdicts.values()) == {"PASS"}, done.stdout  # (the report's rows)


def test_the_scenario_test_example_passes_under_pytest(pytester):
    snippet = next(b for lang, b in BLOCKS if lang == "python" and "def test_speed" in b)
    (pytester.path / "scenarios").symlink_to(ROOT / "scenarios")  # its path is relative to the project
    test_file = pytester.makepyfile(test_readme_speed="import pytest\n\n\n" + snippet)
    result = pytester.runpytest_inprocess(str(test_file), "-p", "no:cacheprovider")
    result.assert_outcomes(passed=3)


def test_every_command_the_readme_names_is_executed():
    named = {c.strip() for c in re.findall(r"`(rehabkit [^`]*)`", README)}
    concrete = {c for c in named if not re.search(r"[A-Z]{2,}|S\.yaml|\[", c) and len(c.split()) > 1}
    here = {"rehabkit validate bad.yaml"}  # (the bare names of commands are not commands to run)
    bare = {"rehabkit run", "rehabkit validate", "rehabkit replay", "rehabkit bridge", "rehabkit plugins",
            "rehabkit schema", "rehabkit sweep", "rehabkit assess"}
    assert concrete - here - bare - set(EXECUTED_ELSEWHERE) == set()
    for command, node in EXECUTED_ELSEWHERE.items():
        file, name = node.split("::")
        assert f"def {name}(" in (ROOT / file).read_text(), node
        assert command.split()[1] in (ROOT / file).read_text(), node  # that test does run the command


def test_the_musculoskeletal_commands_compare_controllers_and_severities(tmp_path):
    """The section's three commands, shortened (6 s sessions, a 2 s serial sweep): PD and assist-as-needed side
    by side on the same person; the severities in order of the help the robot gives."""
    run, replay, sweep = [line.split("#")[0].strip() for line in _block_after("## A musculoskeletal patient",
                                                                              "bash").strip().splitlines()]
    done, args = _run(run + " --set duration=6", tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    out = args[args.index("--out") + 1]
    again = cli(*replay.replace("out/lexos_myoarm", out).split()[1:])
    assert again.returncode in (0, 1), again.stderr
    table = again.stdout
    for measure in ("sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio", "peak_cuff_force_n",
                    "muscle_effort"):
        assert measure in table
    inputs = {k: v for line in table.splitlines() if line.startswith("inputs: ")
              for k, v in (pair.split() for pair in line.removeprefix("inputs: ").split(", "))}
    assert inputs["patient_noise"] == "same"  # the same person, noise for noise
    learned = cli(*_POLICY_REPLAY.replace("out/lexos_myoarm", out).split()[1:])  # the learned policy, same session
    assert learned.returncode in (0, 1), learned.stderr
    inputs = {k: v for line in learned.stdout.splitlines() if line.startswith("inputs: ")
              for k, v in (pair.split() for pair in line.removeprefix("inputs: ").split(", "))}
    assert "policy" in learned.stdout and inputs["patient_noise"] == "same"
    done, args = _run(sweep + " --grid duration=2 --serial --out sev", tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    with open(Path(args[args.index("--out") + 1]) / "aggregate.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["patient"].split("/")[-1].split("_")[0] for r in rows] == ["mild", "moderate", "severe"]
    help_given = [float(r["assistance_ratio.mean"]) for r in rows]
    assert help_given == sorted(help_given) and help_given[-1] > 0.3 > help_given[0]


def test_the_fit_block_is_the_dynamometer_example():
    block = _block_after("## A musculoskeletal patient", "yaml")
    example = yaml.safe_load((ROOT / "examples" / "robots" / "elbow_dynamometer.yaml").read_text())
    assert yaml.safe_load(block)["fit"] == example["patient"]["model"]["fit"]


def test_the_gymnasium_example_runs(monkeypatch, capsys):
    snippet = next(b for lang, b in BLOCKS if lang == "python" and "rehabkit/Scenario-v0" in b)
    monkeypatch.chdir(ROOT)
    exec(compile(snippet, "README.md", "exec"), {})
    assert "tracking" in capsys.readouterr().out


def test_the_learning_block_is_lexos_myoarms():
    block = yaml.safe_load(_block_after("## Learning: scenarios as Gymnasium environments", "yaml"))["learning"]
    scenario = yaml.safe_load((ROOT / "scenarios" / "lexos_myoarm.yaml").read_text())["learning"]
    assert block == {**scenario, "observation": {**scenario["observation"], "layout": "box"}}


def test_the_force_sensing_block_is_the_force_skills():
    block = yaml.safe_load(_block_after("**Force sensing.**", "yaml"))
    scenario = yaml.safe_load((ROOT / "scenarios" / "safety" / "hit_force.yaml").read_text())
    assert block["world"]["loads"] == scenario["world"]["loads"]
    sensor = scenario["sensors"]["ft"]
    assert block["sensors"]["ft"]["type"] == sensor["type"]
    assert block["sensors"]["ft"]["simulated"].items() <= sensor["simulated"].items()


def test_every_option_of_every_command_is_in_the_readme():
    from rehabkit.cli.main import parser

    commands = next(a for a in parser()._actions if a.choices and "run" in a.choices).choices
    missing = {name: [o for a in sub._actions for o in a.option_strings if o.startswith("--") and o != "--help"
                      and o not in README] for name, sub in commands.items()}
    assert {k: v for k, v in missing.items() if v} == {}
    shown = cli("bridge", "--help")  # where the README sends a reader for the options a host passes
    assert shown.returncode == 0 and "--watchdog-ms" in shown.stdout and "--instruments JSON" in shown.stdout
