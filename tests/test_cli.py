"""The command line: exit codes, messages, outputs."""

import contextlib
import io
import json
import os
import subprocess
import warnings

from rehabkit.cli import main
from tests.conftest import ROOT, SCENARIOS
from tests.located import located, refusal, set_located, suggested, where


def cli(*args, cwd=ROOT):
    """``rehabkit ARGS`` run in this process (the command's own ``main``: its exit code, stdout and stderr as a
    process would give them) — a second Python per call cost ~1 s of the suite each."""
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    try:
        os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("default")
            try:
                code = main(list(map(str, args)))
            except SystemExit as exc:  # argparse's own exits (--version, --help, a usage error)
                code = exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 2
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["rehabkit", *args], code, out.getvalue(), err.getvalue())


def test_run_writes_rrd_and_summary_and_exits_0(tmp_path):
    r = cli("run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["passed"] and (tmp_path / "run.rrd").stat().st_size > 100_000
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*tmp"))
    m = summary["metrics"]
    for key in ("tracking_rms_deg", "tracking_max_deg", "continuity_B_position_deg", "continuity_C_velocity_deg_s",
                "continuity_D_acceleration_deg_s2", "ik_roundtrip_position_error_m", "real_time_factor"):
        assert key in m, key
    assert summary["plugins"]["planner"] == {"type": "multi-cubic", "package": "rehabkit", "version": "0.1.0"}
    verdicts = {w[1]: w[0] for w in map(str.split, r.stdout.splitlines())
                if w[:1] in (["PASS"], ["FAIL"])}  # (the report's rows)
    assert verdicts["tracking_rms_deg"] == "PASS"


def test_failed_expectation_exits_1(tmp_path):
    r = cli("run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(tmp_path), "--set",
            "expect.tracking_rms_deg.lt=1e-6")
    assert r.returncode == 1
    verdicts = {w[1]: w[0] for w in map(str.split, r.stdout.splitlines())
                if w[:1] in (["PASS"], ["FAIL"])}  # (the report's rows)
    assert verdicts["tracking_rms_deg"] == "FAIL"
    assert json.loads((tmp_path / "summary.json").read_text())["passed"] is False


def test_validate_reports_location_and_suggestion_and_exits_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\nplanner:\n  type: multicubic\n"
                   "  segment_durations: [2, 2, 2, 2]\ncontroller:\n  type: joint-pd\n  kpp: 3\n")
    r = cli("validate", str(bad))
    assert r.returncode == 2
    assert located(r.stderr) == [(str(bad), 3, 9, "planner.type"), (str(bad), 7, 3, "controller.kpp")], r.stderr
    assert suggested(r.stderr) == ["multi-cubic", "kp"]  # (the fixes)
    assert len(r.stderr.splitlines()) == 2  # (those two, and no traceback)


def test_validate_checks_fixed_targets_against_the_patients_range():
    """The run's setup refusal, before anything runs: located, the joint and the range named, the fix suggested."""
    example = str(ROOT / "examples" / "patient_out_of_range.yaml")
    r = cli("validate", example, str(SCENARIOS / "lexos_patient.yaml"))
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1  # (one error, no traceback)
    assert [(os.path.basename(f), *rest) for f, *rest in located(r.stderr)] == [
        ("hit_roundtrip.yaml", 30, 7, "task.targets.0")], r.stderr
    assert "lexos_patient.yaml: ok (fixed targets within patient P01's ranges)" in r.stdout
    (d,) = refusal(example).diagnostics  # (its fix, a field; the line as said: tests/test_message_wording.py)
    assert d.fix == "move the target into the range, or set patient.outside_rom: nearest to use the nearest " \
        "admissible point"
    r = cli("validate", example, "--set", "patient.outside_rom=nearest")
    assert r.returncode == 0
    assert "target 'A' outside the range of elbow_1: would be replaced by the nearest admissible posture" in r.stdout
    # the envelope's range without a patient: its own range is the fix to name (a profile's choice is not there)
    refused = refusal(SCENARIOS / "hit_roundtrip.yaml", "safety.joints={elbow_1: {range_deg: [20, 80]}}")
    assert where(refused) == [(30, 7, "task.targets.0")]
    assert refused.diagnostics[0].fix == "move the target into the range, or widen safety.joints.elbow_1.range_deg"


def test_missing_file_and_setup_errors_are_messages_not_tracebacks(tmp_path):
    r = cli("run", str(tmp_path / "nope.yaml"))
    assert (r.returncode, r.stderr.split(": ")[0], len(r.stderr.splitlines())) == (2, str(tmp_path / "nope.yaml"), 1)
    r = cli("run", str(SCENARIOS / "hit_roundtrip.yaml"), "--out", str(tmp_path), "--set", "rates.control_hz=300")
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1, r.stderr  # (no traceback)
    assert set_located(r.stderr) == [("rates.control_hz", "rates.control_hz")]


def test_plugins_and_schema_commands():
    r = cli("plugins")
    assert r.returncode == 0
    assert "planner    multi-cubic      rehabkit 0.1.0" in r.stdout and "segment_durations: list[float]" in r.stdout
    assert "extension  rehab            sections outcomes:, patient:" in r.stdout  # the layers and their sections
    schema = json.loads(cli("schema").stdout)
    assert schema["title"] == "rehabkit scenario" and "planner" in schema["$defs"]["Scenario"]["properties"]
    listed = json.loads(cli("plugins", "--json").stdout)
    rows = listed if isinstance(listed, list) else listed.get("plugins", listed)
    assert "ompl-joint" in json.dumps(rows) and "cartesian" in json.dumps(rows)


def test_a_plugins_reference_gives_every_setting_with_units_and_defaults_and_its_metrics():
    r = cli("plugins", "--fields", "dh")
    assert r.returncode == 0
    assert "  table: list[DHRowSpec] = required" in r.stdout
    assert "      mass: float = required (> 0) — [kg]" in r.stdout  # a joint's setting, under the joints, its bound
    r = cli("plugins", "--fields", "ompl-joint")
    clearance = "  clearance_m: float = 0.01 (≥ 0) — distance below which a link counts as touching the world [m]"
    assert clearance in r.stdout
    assert "  states_checked [count] — states checked for collision by MuJoCo" in r.stdout
    r = cli("plugins", "--fields", "musculoskeletal")  # a patient's: nested impairments, with their units
    assert "  model: Literal['myoarm', 'myoelbow'] = 'myoarm'" in r.stdout
    assert "threshold_l0_s: float = 0.3" in r.stdout and "peak_cuff_force_n [N]" in r.stdout
    r = cli("plugins", "--fields", "multicubic")
    assert (r.returncode, suggested(r.stderr)) == (2, ["multi-cubic"])


def test_a_key_written_into_a_git_tree_that_does_not_ignore_it_is_warned_of(tmp_path):
    import subprocess

    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    r = cli("keys", "new", "arm-1", "--out", str(tmp_path / "arm.key"), cwd=tmp_path)
    assert r.returncode == 0 and "warning: " in r.stderr and "git does not ignore it" in r.stderr
    assert f"Add it to {tmp_path / '.gitignore'}" in r.stderr
    (tmp_path / ".gitignore").write_text("*.key\n")
    quiet = cli("keys", "new", "arm-2", "--out", str(tmp_path / "arm2.key"), cwd=tmp_path)
    assert quiet.returncode == 0 and quiet.stderr == ""


def test_the_link_line_says_why_states_were_dropped():
    """'117 states refused' read as an attack; most were the host's own stale states."""
    from rehabkit.cli.run_report import _link

    m = {"states_dropped": 117, "states_dropped_stale": 115, "states_dropped_out_of_order": 2}
    assert _link(m) == ["  LINK    117 states dropped (115 stale, 2 out of order)"]
