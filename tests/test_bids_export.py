"""A study's runs as Motion-BIDS (``rehabkit export bids``, ``rehabkit sweep --bids``) and its progress page
(``rehabkit progress``): the README's study commands run as written (short sessions), the official validator finds
no error and no warning in the datasets they make, pybids reads the joint angles back equal to the bag's to the
decimals printed, and adding runs again is safe and resumable.

Short runs (0.4 s of the L-Exos patient each), made once for the module, on the worker of that scenario's own test."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from rehabkit.bids.run_folder import ExportError, peek_run
from rehabkit.testing import group
from tests.conftest import ROOT, SCENARIOS
from tests.test_cli import cli

# on the worker that runs scenarios/lexos_patient.yaml's own test: the L-Exos and its person are loaded there already
pytestmark = pytest.mark.xdist_group(group(SCENARIOS / "lexos_patient.yaml"))
README = (ROOT / "README.md").read_text()
BLOCK = re.search(r"## A study's dataset.*?```bash\n(.*?)```", README, re.S)[1]
SHORT = ["--set", "duration=0.4"]  # (a rehearsal of the first 0.4 s: the task unfinished, exit 1)


def _args(line: str, tmp) -> list[str]:
    """A README line's arguments, its paths under ``out/`` sent to ``tmp``."""
    return [str(tmp / a.removeprefix("out/")) if a.startswith("out/") else a for a in shlex.split(line.split("#")[0])]


def _validate(dataset) -> dict:
    done = subprocess.run(["bids-validator-deno", str(dataset), "--format", "json", "--max-rows", "-1"],
                          capture_output=True, text=True, check=False)
    assert done.stdout, done.stderr
    return json.loads(done.stdout)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """The README's study block, line by line: sessions run (short), exported, validated, drawn; then its sweep."""
    tmp = tmp_path_factory.mktemp("study")
    said = {}
    for line in filter(None, (x.strip() for x in BLOCK.splitlines())):
        args = _args(line, tmp)
        if args[0] == "bids-validator-deno":
            said["validator"] = _validate(args[1])
            continue
        assert args[0] == "rehabkit", line
        extra = SHORT if args[1] == "run" else [*SHORT, "--seeds", "2", "--grid",
                                                "patient.model.voluntary.participation=0.8"] \
            if args[1] == "sweep" else []
        done = cli(*args[1:], *extra)
        assert done.returncode in ((0, 1) if args[1] in ("run", "sweep") else (0,)), (line, done.stderr)
        said[args[1]] = (args, done)
    return tmp, said


def test_the_study_dataset_passes_the_validator_with_no_error_and_no_warning(study):
    tmp, said = study
    raw = said["validator"]
    assert raw["issues"]["issues"] == []
    assert raw["summary"]["subjects"] == ["P01"] and sorted(raw["summary"]["sessions"]) == ["1", "2"]
    assert _validate(tmp / "study" / "bids" / "derivatives" / "rehabkit")["issues"]["issues"] == []


def test_pybids_reads_the_joint_angles_back_as_the_bag_holds_them(study):
    import bids

    from rehabkit.bags.session_bag import read_session

    tmp, _ = study
    layout = bids.BIDSLayout(tmp / "study" / "bids", validate=False)
    files = layout.get(suffix="motion", extension=".tsv", tracksys="lexos")
    assert [(f.entities["subject"], f.entities["session"]) for f in files] == [("P01", "1"), ("P01", "2")]
    for f in files:
        meta = f.get_metadata()
        channels = layout.get(suffix="channels", extension=".tsv", session=f.entities["session"],
                              tracksys="lexos")[0].get_df()
        data = np.loadtxt(f.path, delimiter="\t")  # (numbers only: loadtxt refuses a header or "n/a")
        assert data.shape[1] == len(channels) == meta["MotionChannelCount"] == 25
        counts = channels["type"].value_counts().to_dict()
        assert counts == {"JNTANG": 4, "MISC": 18, "POS": 3}
        assert (meta["JNTANGChannelCount"], meta["MISCChannelCount"], meta["POSChannelCount"]) == (4, 18, 3)
        assert meta["SamplingFrequency"] == 1000 and data.shape[0] == 400
        bag = read_session(tmp / "study" / f"ses{f.entities['session']}" / "run.mcap", roles=())
        angles = data[:, (channels["type"] == "JNTANG").to_numpy()]
        largest = np.abs(angles - np.degrees(bag.joints.values)).max()
        assert largest <= 0.5e-5 + 1e-9  # (5 decimals of a degree)
        events = layout.get(suffix="events", extension=".tsv", session=f.entities["session"])[0].get_df()
        assert {"target_shown", "safety_intervention"} <= set(events["trial_type"])
        assert events["HED"].str.startswith("(").all() and (events["onset"] >= 0).all()


def test_the_sweep_of_simulated_people_is_a_dataset_of_its_own(study):
    tmp, said = study
    args, done = said["sweep"]
    dataset = Path(args[args.index("--bids") + 1])
    report = _validate(dataset)
    assert report["issues"]["issues"] == []
    people = (dataset / "participants.tsv").read_text().splitlines()
    assert [row.split("\t")[0] for row in people[1:]] == ["sub-P01s0", "sub-P01s1"]
    assert "simulated-arm" in people[1] and "(simulated)" in json.loads(
        (dataset / "dataset_description.json").read_text())["Name"]
    sessions = (dataset / "sub-P01s1" / "sub-P01s1_sessions.tsv").read_text().splitlines()
    assert sessions[0].split("\t")[-1] == "patient_model_voluntary_participation"
    assert sessions[1].startswith("ses-point1") and sessions[1].endswith("\t0.8")


def test_the_progress_page_draws_and_says_each_change(study):
    tmp, said = study
    args, done = said["progress"]
    page = tmp / "study" / "bids" / "derivatives" / "rehabkit" / "progress.html"
    text = page.read_text()
    assert text.count("src='data:image/png;base64,") == 1
    said = dict(line.removeprefix("sub-P01: ").split(": ", 1) for line in done.stdout.splitlines()[:-1])
    assert {"Smoothness (SPARC)", "Time to target", "Peak interaction force", "Range of motion, q4_elbow"} <= set(said)
    assert re.match(r"(rose|fell) from \S+ to \S+ \([+-]\S+\): (more|less) help from the robot — (better|worse)$",
                    said["Assistance ratio (robot's share of the work)"])
    assert "Range of motion, q4_elbow" in text


def test_runs_added_again_are_not_doubled_and_a_killed_export_is_made_good(study, tmp_path, monkeypatch):
    from rehabkit.bids import commands, derivatives

    tmp, _ = study
    ses1, ses2 = tmp / "study" / "ses1", tmp / "study" / "ses2"
    dataset = tmp_path / "bids"
    assert cli("export", "bids", str(ses1), "--out", str(dataset)).returncode == 0
    again = cli("export", "bids", str(ses1), "--out", str(dataset))
    assert again.returncode == 0 and again.stdout.startswith("skipped")

    def killed(*a, **k):
        raise KeyboardInterrupt  # (killed after the motion files, before scans.tsv listed the run)
    monkeypatch.setattr(derivatives, "add_run", killed)
    with pytest.raises(KeyboardInterrupt):
        commands.export_runs([ses2], dataset, say=lambda _: None)
    assert len(list(dataset.glob("sub-P01/ses-2/motion/*"))) == 10  # written, not listed: not in the dataset
    assert not (dataset / "sub-P01" / "ses-2" / "sub-P01_ses-2_scans.tsv").exists()
    monkeypatch.undo()
    done = cli("export", "bids", str(ses1), str(ses2), "--out", str(dataset))
    said = [line.split()[0] for line in done.stdout.splitlines()]
    assert done.returncode == 0 and said.count("skipped") == 1 and said.count("added") == 1
    made = sorted(p.relative_to(dataset) for p in dataset.rglob("*") if p.is_file() and ".rehabkit" not in p.parts)
    whole = sorted(p.relative_to(tmp / "study" / "bids") for p in (tmp / "study" / "bids").rglob("*")
                   if p.is_file() and ".rehabkit" not in p.parts and p.name != "progress.html")
    assert made == whole  # (the same files as the dataset made in one go: nothing left over, nothing missing)
    for f in made:
        if f.suffix == ".tsv" and "motion" in f.parts:
            assert (dataset / f).read_bytes() == (tmp / "study" / "bids" / f).read_bytes(), f


def test_bad_input_is_refused_with_exit_2_before_anything_is_written(study, tmp_path):
    tmp, _ = study
    folder = tmp_path / "nobag"
    shutil.copytree(tmp / "study" / "ses1", folder)
    (folder / "run.mcap").unlink()
    done = cli("export", "bids", str(folder), "--out", str(tmp_path / "ds"))
    assert done.returncode == 2
    with pytest.raises(ExportError) as no_bag:  # what it says: the bag missing, and to run with --bag
        peek_run(folder)
    assert (no_bag.value.where, no_bag.value.fix) == (str(folder / "run.mcap"), f"run with --bag (`rehabkit replay "
                                                      f"{folder} --bag` makes a simulated session again, same seed "
                                                      "and inputs)")
    assert not list((tmp_path / "ds").glob("sub-*"))
    assert cli("export", "bids", str(tmp_path / "none"), "--out", str(tmp_path / "ds")).returncode == 2
    assert cli("progress", str(tmp / "study" / "bids"), "--participant", "P99").returncode == 2
    bad = tmp_path / "study.yaml"
    bad.write_text("authors: one\n")
    assert cli("export", "bids", str(tmp / "study" / "ses1"), "--out", str(tmp_path / "ds"), "--study",
               str(bad)).returncode == 2


def test_the_exporters_own_check_refuses_what_the_validator_does_not(tmp_path):
    from rehabkit.bids.tables import OutputError, read_motion, write_motion

    data = np.array([[1.234567, np.nan], [-0.0000004, 2.0]])
    assert write_motion(tmp_path / "a_motion.tsv", data, [5, 3]) <= 0.5e-5
    assert (tmp_path / "a_motion.tsv").read_text() == "1.23457\tn/a\n0\t2\n"
    for text in ("angle\tforce\n1\t2\n", "1\t2\n3\n", "1\t2\t3\n"):  # a header; a row short; a column more
        (tmp_path / "b_motion.tsv").write_text(text)
        with pytest.raises(OutputError):
            read_motion(tmp_path / "b_motion.tsv", 2)


def test_a_user_robots_run_exports_from_anywhere_with_its_targets_named_in_order(tmp_path, monkeypatch):
    """The README's URDF arm run from another folder (its robot file relative to its scenario, not to the run
    folder: the export built the robot from the wrong place and refused), its events naming the targets as the arm
    goes to them — left, then right (the plan's start posture shown at the same instant was named instead of left)."""
    from rehabkit.cli.main import main

    monkeypatch.chdir(tmp_path)
    robot = ROOT / "examples" / "robots" / "urdf_arm4.yaml"
    run = ["run", str(robot), "--bag", "--out", "run", "--set", "duration=4.5"]
    assert main(run) == 1  # (its task takes 11 s: unfinished)
    assert main(["export", "bids", "run", "--out", "ds", "--participant", "rig"]) == 0
    (events,) = (tmp_path / "ds").glob("sub-rig/ses-*/motion/*_events.tsv")
    rows = [line.split("\t") for line in events.read_text().splitlines()[1:]]
    assert [(float(r[0]), r[3]) for r in rows if r[2] == "target_shown"] == [(0.0, "left"), (3.751, "right")]


def test_the_progress_page_says_which_way_each_change_goes():
    from rehabkit.bids.progress import MEASURES, _change

    for name, first, last, words in (("path_length_ratio", 1.12, 1.18, "less straight — worse"),
                                     ("time_to_target_s", 3.0, 2.0, "faster — better"),
                                     ("sparc", -2.5, -2.0, "smoother — better")):
        title, unit, better, up, down = MEASURES[name]
        assert _change(title, unit, first, last, better, up, down, first).endswith(words)
