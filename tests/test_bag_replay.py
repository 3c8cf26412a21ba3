"""A real session's bag, replayed: bags written by rosbags' writer (``examples/ros_session/record_session.py``, not
rehabkit's own writer) put against the session's controller and a softer one, a bag with renamed topics and a gap
(SQLite storage), and bags that do not fit said at the bag. The README section's commands, as written."""

import importlib.util
import json
import re
import shlex

import numpy as np
import pytest

from rehabkit.api import load_scenario
from rehabkit.cli import exits
from rehabkit.ros.replay.bag_replay import replay_bag
from rehabkit.ros.replay.session_bag import BagError, read_session, reading_once
from tests.conftest import ROOT
from tests.located import at_bag, set_located
from tests.test_cli import cli

SECTION = (ROOT / "README.md").read_text().split("## A real session's bag, replayed")[1].split("\n## ")[0]
BLOCKS = [b.strip().splitlines() for b in re.findall(r"```bash\n(.*?)```", SECTION, re.S)]
SESSION = ROOT / "examples" / "ros_session" / "arm4_session.yaml"


def _recorder():
    spec = importlib.util.spec_from_file_location("record_session", SESSION.parent / "record_session.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _command(line: str) -> list[str]:
    return shlex.split(line.split("#")[0])


@pytest.fixture(scope="module", autouse=True)
def _each_bag_deserialised_once():
    """The module's replays, refusals and reads go over the same three bags: their messages deserialised once for
    all of them (``reading_once``, as a replay shares its bag's with the recorded-wrench patient it builds; a read of
    the 8-s session's 16,000 messages is ~0.3 s). Each bag is still opened and listed by rosbags at every read, and
    its messages read by rosbags once."""
    with reading_once():
        yield


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """The README's two recordings (its `python` lines, in this process: the session is run once for both)."""
    where = tmp_path_factory.mktemp("bags")
    rec = _recorder()
    made = {}
    for block in BLOCKS:
        args = _command(block[0])
        assert args[:2] == ["python", "examples/ros_session/record_session.py"]
        ns = argparse_like(args[2:])
        made[args[2].split("/")[-1]] = (where / ns["bag"], rec.record(where / ns["bag"], SESSION, ns["topics"],
                                                                    ns["gap"], ns["storage"]))
    return made


def argparse_like(args: list[str]) -> dict:
    out = {"bag": args[0].split("/")[-1], "topics": {}, "gap": None, "storage": "mcap"}
    for flag, value in zip(args[1::2], args[2::2]):
        if flag == "--topic":
            role, topic = value.split("=", 1)
            out["topics"][role] = topic
        elif flag == "--gap":
            out["gap"] = tuple(map(float, value.split(",")))
        elif flag == "--storage":
            out["storage"] = value
    return out


def test_the_sessions_own_controller_replays_the_session(bags, tmp_path):
    """With the controller it was recorded with, the person's recorded wrench played back open loop gives the
    session again: the joints within 1e-4° (measured 3.1e-6°), every outcome measure within 1e-4 relative."""
    bag, counts = bags["session"]
    assert counts == {"/joint_states": 8000, "/wrench": 8000, "/targets": 3}
    rep = replay_bag(bag, SESSION, out_dir=tmp_path)
    session = read_session(bag)
    assert np.degrees(np.abs(session.joints.at(rep.result.trace.t) - rep.result.trace.q)).max() < 1e-4
    rows = {k: (a, b) for k, a, b in rep.rows()}
    assert rows["reaches_completed"] == (3.0, 3.0)
    for key in ("sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio", "peak_interaction_force_n",
                "rom_deg_shoulder", "rom_deg_wrist"):
        a, b = rows[key]
        assert abs(a - b) <= 1e-4 * abs(a), (key, a, b)
    assert rows["time_to_target_s"][0] == pytest.approx(1.540, abs=1e-3)
    # the scenario it ran in: the targets shown in the world, back in the arm's base frame (0.8 m below)
    replayed = load_scenario(tmp_path / "replayed_session.yaml").model
    shown = {t.name: t.position for t in replayed.task.targets if t.position is not None}
    assert np.allclose(shown["shown_1"], [0.35, 0.2, 0.15], atol=1e-6)
    assert [e.at for e in replayed.task.events] == [0.5, 4.0, 6.0]
    assert replayed.patient.model.type == "recorded-wrench" and replayed.patient.id == "S01"
    written = json.loads((tmp_path / "session.json").read_text())
    assert written["metrics"]["reaches_completed"] == 3.0 and written["gaps"] == []


def test_a_softer_controller_side_by_side(bags, tmp_path):
    """The README's second replay: the same pushes against joint PD at half the bandwidth — one reach of three
    completed within 1 cm, less of the work done by the robot."""
    (bag, _), line = bags["session"], BLOCKS[0][2]
    args = _command(line)
    args[2] = str(bag)
    done = cli(*args[1:], "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    table = {row.split()[0]: row.split()[1:] for row in done.stdout.splitlines()[2:] if row and row[0].isalpha()}
    assert table["reaches_completed"] == ["3", "1"]
    assert float(table["tracking_rms_deg"][1]) > 3.0
    assert float(table["assistance_ratio"][1]) < float(table["assistance_ratio"][0])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["plugins"]["patient"]["type"] == "recorded-wrench"


def test_renamed_topics_are_mapped_and_a_gap_is_said_and_bridged(bags, tmp_path):
    bag, counts = bags["renamed"]
    assert counts == {"/arm/joint_states": 7700, "/cuff/wrench": 7700, "/task/targets": 3}  # (0.3 s dropped)
    unmapped = cli("replay", bag, "--scenario", SESSION, "--out", tmp_path / "unmapped")
    assert unmapped.returncode == 2
    with pytest.raises(BagError) as refused:  # (every role at once)
        read_session(bag)
    assert [role for role, _ in refused.value.problems] == ["joint_states", "wrench", "targets"]
    assert at_bag(unmapped.stderr) == [(str(bag), role) for role in ("joint_states", "wrench", "targets")]
    args = _command(BLOCKS[1][1])
    args[2] = str(bag)
    done = cli(*args[1:], "--out", tmp_path / "mapped")
    assert done.returncode == 0, done.stderr
    gaps = [line for line in done.stdout.splitlines() if line.startswith("  BAG")]  # (said before the replay runs)
    assert gaps == [f"  BAG  {bag}: {topic} has no messages for 0.301 s from t = 1.999 s: bridged by interpolation"
                    for topic in ("/arm/joint_states", "/cuff/wrench")]
    assert done.stdout.index("  BAG") < done.stdout.index("metric ")
    table = {row.split()[0]: row.split()[1:] for row in done.stdout.splitlines() if row and row[0].isalpha()}
    assert table["reaches_completed"] == ["3", "3"]
    notes = json.loads((tmp_path / "mapped" / "summary.json").read_text())["notes"]
    assert any("/cuff/wrench has no messages for 0.301 s" in n["text"] for n in notes)


def test_bags_that_do_not_fit_are_said_at_the_bag(bags, tmp_path):
    bag, _ = bags["session"]
    other = cli("replay", bag, "--scenario", ROOT / "examples" / "robots" / "mjcf_arm5.yaml")
    assert other.returncode == 2
    assert at_bag(other.stderr) == [(str(bag), "joint_states")]
    typed = cli("replay", bag, "--scenario", SESSION, "--topics", "wrench=/joint_states")
    assert typed.returncode == 2
    assert at_bag(typed.stderr) == [(str(bag), "wrench")]
    frame = cli("replay", bag, "--scenario", SESSION, "--set", "patient.model.frame=nowhere", "--out", tmp_path)
    assert frame.returncode == 2
    assert set_located(frame.stderr) == [("patient.model.frame", "patient.model.frame")]
    no_scenario = cli("replay", bag)
    assert no_scenario.returncode == 2 and exits.last_refusal.code == "bag-needs-scenario"
    assert exits.last_refusal.option == "--scenario"
    fields = cli("plugins", "--fields", "recorded-wrench")
    assert fields.returncode == 0 and "max_gap_s" in fields.stdout and "reaction" in fields.stdout


def test_rehabkits_own_bag_replays_as_a_robots_would(tmp_path):
    """A run's run.mcap (the person's wrench on /wrench, each movement's goal on /targets) is a session like a
    robot's: replayed with the defaults on the scenario it ran, it gives the run again."""
    from rehabkit.api import run_scenario

    run = run_scenario(SESSION, {"ros": {"bag": True}, "duration": 4.5}, out_dir=tmp_path / "run")
    rep = replay_bag(tmp_path / "run" / "run.mcap", SESSION, out_dir=tmp_path / "replay")
    assert np.degrees(np.abs(run.trace.q - rep.result.trace.q)).max() < 1e-4
    rows = {k: (a, b) for k, a, b in rep.rows()}
    assert rows["reaches_completed"] == (1.0, 1.0)  # (the second reach is cut at 4.5 s)
    for key in ("sparc", "time_to_target_s", "peak_interaction_force_n", "rom_deg_elbow"):
        assert rows[key][1] == pytest.approx(rows[key][0], rel=1e-4), key
        assert rows[key][1] == pytest.approx(run.metrics[key], rel=1e-4), key


def test_a_role_left_unmapped_is_said_and_one_left_out_on_purpose_keeps_the_scenarios_own(bags, tmp_path):
    """Mapping only the joint states of a renamed bag is refused at the wrench (not a silent replay without the
    person); ``wrench=`` leaves the person out on purpose: the scenario's own simulated person is in the robot, and
    the session's person-related measures are unknown rather than none."""
    bag, _ = bags["renamed"]
    half = cli("replay", bag, "--scenario", SESSION, "--topics", "joint_states=/arm/joint_states")
    assert half.returncode == 2
    assert at_bag(half.stderr) == [(str(bag), "wrench"), (str(bag), "targets")]  # (the targets too: renamed)
    assert "or --topics wrench= to replay without it" in half.stderr
    done = cli("replay", bag, "--scenario", SESSION, "--out", tmp_path, "--topics",
               "joint_states=/arm/joint_states,wrench=,targets=/task/targets")
    assert done.returncode == 0, done.stderr
    table = {row.split()[0]: row.split()[1:] for row in done.stdout.splitlines() if row and row[0].isalpha()}
    assert table["peak_interaction_force_n"][0] == "—" and float(table["peak_interaction_force_n"][1]) > 10
    assert table["reaches_completed"] == ["3", "3"]
    assert json.loads((tmp_path / "summary.json").read_text())["plugins"]["patient"]["type"] == "simulated-arm"
