"""Bags a ROS user can trust. A Panda session with a mixed task: its posture targets stay postures
(``/targets/joint_states``), and its replay with the same controller reaches the same postures on the session's time
base. An SO-101 session, one plan through via points, replays as that plan (told from its reference; without it,
from the measured joints), without a person where its bag has none; its run folder's replay says its deviation too.
``/tf`` is the URDF's own tree (checked against the file's joints, parsed here): the Panda's mimic finger under its
own parent, the xArm's own ``world → link_base`` with the scenario's placement. A bag's bad content, written by
rosbags' own writer (NaN, inf, a joint or a wrench frame the robot lacks), is refused at the bag, topic and stamp
before anything runs, leaving no folder, or said — and the replay says its largest deviation from the session."""

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from rehabkit.api import load_scenario, run_scenario
from rehabkit.ros.replay.bag_content import BagError
from rehabkit.ros.replay.bag_replay import replay_bag
from tests.conftest import ROOT
from tests.located import at_bag
from tests.test_cli import cli
from tests.test_ros_bag import read

PANDA = ROOT / "tests" / "data" / "panda_mixed_session.yaml"
ERD = Path(__import__("cmeel").__file__).parent.parent / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
EPOCH = 1_700_000_000 * 1_000_000_000  # the bad bags' session start (Unix time, as a robot stamps it)
NO_REFERENCE = ("no joints' reference (rehabkit's bags: /reference/joint_states): plans told apart by the measured "
                "joints' speed (a target shown while they moved: a via point of the plan under way): ")
ENDS = ("; each plan's last movement given until the next plan began, or the session's end (one that ended sooner is "
        "replayed slower)")


def urdf_joints(path: Path) -> dict[str, tuple[str, str, ET.Element]]:
    """The file's own joints (not a transmission's): child link → (parent link, joint type, the element)."""
    robot = ET.parse(path).getroot()
    return {j.find("child").get("link"): (j.find("parent").get("link"), j.get("type"), j)
            for j in robot.findall("joint")}


def parents(messages: dict) -> dict[str, str]:
    """Each frame's parent, as /tf_static and the first /tf give them."""
    tf = [*messages["/tf_static"][0][1].transforms, *messages["/tf"][0][1].transforms]
    return {t.child_frame_id: t.header.frame_id for t in tf}


def matrix(t) -> np.ndarray:
    r, p = t.transform.rotation, t.transform.translation
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = pin.Quaternion(r.w, r.x, r.y, r.z).toRotationMatrix(), (p.x, p.y, p.z)
    return m


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    """The session (with --bag), and its replay on the same scenario with --bag."""
    where = tmp_path_factory.mktemp("panda")
    run = run_scenario(PANDA, {"ros": {"bag": True}}, out_dir=where / "run")
    rep = replay_bag(where / "run" / "run.mcap", PANDA, {"wrench": ""}, ["ros.bag=true"], where / "replay")
    return run, read(where / "run" / "run.mcap")[1], rep, read(where / "replay" / "run.mcap")[1]


def test_a_pandas_postures_stay_postures_and_its_replay_reaches_them(panda):
    """Each posture target on /targets/joint_states as the task gives it (a redundant arm: its hand pose would be
    solved by IK to another posture — joint 3 was 46.5° off, joint 1's range 11.6° replayed for 57.7° recorded);
    the hand targets as given. The replay follows the session to 1e-6° (measured 4e-14°), says so, and its bag is
    stamped on the session's time base."""
    run, messages, rep, replayed = panda
    postures = [m for _, m in messages["/targets/joint_states"]]
    home = np.radians([0, -30, 0, -130, 0, 100, 45, 0])
    home[7], tilt = 0.02, np.radians([50, 10, -60, -110, 40, 120, 0, 0])
    tilt[7] = 0.035
    assert [list(m.name) for m in postures] == [list(run.summary["per_joint"])] * 3
    np.testing.assert_allclose([m.position for m in postures], [home, tilt, home], atol=1e-15)
    (point,), (pose,) = [m for _, m in messages["/targets"]], [m for _, m in messages["/targets/pose"]]
    assert point.header.frame_id == pose.header.frame_id == "panda_link0"
    assert (point.point.x, point.point.y, point.point.z) == pytest.approx((0.45, 0.25, 0.45), abs=1e-12)
    o = pose.pose.orientation
    assert abs(o.x) == pytest.approx(1.0, abs=1e-12)  # (rpy 180, 0, 0)
    recorded = np.array([m.position for _, m in messages["/joint_states"]])
    assert recorded.shape == rep.result.trace.q.shape
    gone = np.abs(recorded - rep.result.trace.q)
    assert np.degrees(gone[:, :7]).max() < 1e-6 and gone[:, 7].max() < 1e-9
    arm, finger = rep.original["deviation"]
    assert (arm["unit"], finger["unit"], finger["joint"]) == ("deg", "m", "panda_finger_joint1")
    assert arm["value"] == pytest.approx(np.degrees(gone[:, :7]).max(), abs=1e-12) and arm["value"] < 1e-6
    first = [s for s, _ in messages["/joint_states"]][0]
    assert [s for s, _ in replayed["/joint_states"]][:2] == [first, first + 1_000_000]


def test_tf_is_the_urdfs_own_tree(panda, tmp_path):
    """Every joint of the URDF (parsed here) from its own parent, the root under the scene's world: Panda's mimic
    finger under panda_hand (was panda_hand_tcp), where its leader puts it; every link where Pinocchio's forward
    kinematics has it. The xArm's own world → link_base stays (was world → base → link_base), the scenario's
    placement before it."""
    run, messages, _, _ = panda
    urdf = ERD / "panda_description" / "urdf" / "panda.urdf"
    joints, tree = urdf_joints(urdf), parents(messages)
    assert tree == {**{child: parent for child, (parent, _, _) in joints.items()}, "panda_link0": "world"}
    assert tree["panda_rightfinger"] == "panda_hand"
    k = 250  # (a logged step: /tf's, against the robot's own kinematics at the joints it logged)
    stamp, tf = messages["/tf"][k]
    q = run.trace.q[10 * k]
    assert [s for s, _ in messages["/joint_states"]][10 * k] == stamp
    frames = {t.child_frame_id: t for t in [*messages["/tf_static"][0][1].transforms, *tf.transforms]}

    def in_world(link: str) -> np.ndarray:
        return matrix(frames[link]) if frames[link].header.frame_id == "world" else \
            in_world(frames[link].header.frame_id) @ matrix(frames[link])

    model = pin.buildModelFromUrdf(str(urdf))  # (Pinocchio's own reading of the file: the finger a joint of its own)
    data = model.createData()
    full = np.concatenate([q, [q[7]]])  # (the mimic finger at its leader's value)
    pin.framesForwardKinematics(model, data, full)
    worst = max(np.abs(in_world(link) - data.oMf[model.getFrameId(link)].homogeneous).max() for link in frames
                if link != "world" and model.existFrame(link))
    assert worst < 1e-12
    right = matrix(frames["panda_rightfinger"])
    assert right[:3, 3] == pytest.approx([0.0, -q[7], 0.0584], abs=1e-15) and q[7] > 0.01
    # the xArm: its URDF's world is the scene's, the placement before its world → link_base
    xarm = ERD / "xarm_description" / "urdf" / "xarm7.urdf"
    (tmp_path / "xarm.yaml").write_text(yaml.safe_dump({
        "name": "xarm7", "robot": {"type": "urdf", "file": str(xarm), "ee_frame": "link7",
                                   "base": {"position": [0.1, 0.2, 0.8]}},
        "planner": {"type": "multi-cubic", "segment_durations": [0.2]}, "controller": {"type": "joint-pd"},
        "task": {"targets": [{"name": "A", "joints": [0, 10, 0, 30, 0, 20, 0]}, {"name": "B", "same_as": "A"}]},
        "duration": 0.05, "ros": {"bag": True}}))
    run_scenario(tmp_path / "xarm.yaml", out_dir=tmp_path / "xarm")
    _, messages = read(tmp_path / "xarm" / "run.mcap")
    joints, tree = urdf_joints(xarm), parents(messages)
    assert joints["link_base"][0] == "world"
    assert tree == {child: parent for child, (parent, _, _) in joints.items()}  # (no frame of rehabkit's own)
    base = next(t for t in messages["/tf_static"][0][1].transforms if t.child_frame_id == "link_base")
    assert matrix(base) == pytest.approx(np.array([[1, 0, 0, 0.1], [0, 1, 0, 0.2], [0, 0, 1, 0.8], [0, 0, 0, 1]]))


def test_a_mimic_joint_is_at_its_leaders_value_times_its_multiplier_plus_its_offset():
    """The URDF's kinematics as robot_state_publisher reads them: a mimic joint follows its leader (multiplier,
    offset), a joint moves after its origin, and a transmission's <joint> is no joint of the tree."""
    from rehabkit.ros.urdf_tree import parse_urdf

    tree = parse_urdf("""<robot name="m"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 2"/>
        <origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/></joint>
      <joint name="k" type="prismatic"><parent link="a"/><child link="c"/><axis xyz="1 0 0"/>
        <mimic joint="j" multiplier="-2" offset="0.1"/></joint>
      <transmission name="t"><joint name="j"/></transmission></robot>""")
    assert (tree.root, [(j.name, j.parent, j.child) for j in tree.joints]) == ("a", [("j", "a", "b"), ("k", "a", "c")])
    values = tree.joint_values({"j": 0.3})
    assert values == {"j": 0.3, "k": pytest.approx(-0.5)}
    j, k = tree.joints
    np.testing.assert_allclose(k.motion(values["k"]), [[1, 0, 0, -0.5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                               atol=1e-15)
    turn = np.pi / 2 + 0.3
    np.testing.assert_allclose(j.motion(0.3), [[np.cos(turn), -np.sin(turn), 0, 0], [np.sin(turn), np.cos(turn), 0, 0],
                                               [0, 0, 1, 1], [0, 0, 0, 1]], atol=1e-15)


# -- a bag's bad content: a two-joint arm with a slide (tests/data/slide2.urdf), its sessions written by rosbags --

SLIDE_SCENARIO = {
    "name": "slide2-session", "robot": {"type": "urdf", "file": str(ROOT / "tests" / "data" / "slide2.urdf"),
                                        "ee_frame": "l2"},
    "planner": {"type": "multi-cubic", "segment_durations": [0.5]},
    "controller": {"type": "joint-pd", "gains": "auto", "feedforward": "inverse-dynamics"},
    "task": {"targets": [{"name": "A", "joints": [0, 0.02]}, {"name": "B", "joints": [20, 0.1]}]}, "duration": 1.0}


def write_session(bag: Path, *, nan_position_at: int | None = None, inf_wrench_at: int | None = None,
                  nan_target: bool = False, extra_joint: str | None = None, nan_effort_at: int | None = None,
                  wrench_frame: str = "l2") -> Path:
    """A 1 s session of the slide arm at 100 Hz as a lab's recorder writes it (rosbags' writer): joint states, a
    person's wrench in ``wrench_frame``, two posture targets; the faults asked for at the message indices given."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time, Vec = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"], T["geometry_msgs/msg/Vector3"]
    JS, WS, W = T["sensor_msgs/msg/JointState"], T["geometry_msgs/msg/WrenchStamped"], T["geometry_msgs/msg/Wrench"]

    def header(ns: int, frame: str = ""):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)

    names = ["j1", "slide"] + ([extra_joint] if extra_joint else [])
    shutil.rmtree(bag, ignore_errors=True)
    with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        joints = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        wrench = w.add_connection("/wrench", "geometry_msgs/msg/WrenchStamped", typestore=ts)
        targets = w.add_connection("/targets", "sensor_msgs/msg/JointState", typestore=ts)
        for k in range(100):
            t, ns = k / 100, EPOCH + k * 10_000_000
            s = min(1.0, t / 0.5) ** 2 * (3 - 2 * min(1.0, t / 0.5))  # (A to B in 0.5 s, then held)
            q = np.array([np.radians(20) * s, 0.02 + 0.08 * s] + ([0.01] if extra_joint else []))
            effort = np.zeros(len(names))
            if k == nan_position_at:
                q[1] = np.nan
            if k == nan_effort_at:
                effort[0] = np.nan
            w.write(joints, ns, ts.serialize_cdr(JS(header=header(ns), name=names, position=q,
                                                    velocity=np.zeros(len(names)), effort=effort), JS.__msgtype__))
            f = [0.0, 2.0, np.inf if k == inf_wrench_at else 0.0]
            w.write(wrench, ns, ts.serialize_cdr(WS(header=header(ns, wrench_frame), wrench=W(
                force=Vec(x=f[0], y=f[1], z=f[2]), torque=Vec(x=0.0, y=0.0, z=0.0))), WS.__msgtype__))
        for i, posture in enumerate(([0.0, 0.02], [np.nan if nan_target else np.radians(20), 0.1])):
            ns = EPOCH + i * 10_000_000
            w.write(targets, ns, ts.serialize_cdr(JS(header=header(ns), name=["j1", "slide"], position=np.array(
                posture), velocity=np.zeros(0), effort=np.zeros(0)), JS.__msgtype__))
    return bag


@pytest.fixture(scope="module")
def slide(tmp_path_factory) -> Path:
    where = tmp_path_factory.mktemp("slide")
    (where / "slide2.yaml").write_text(yaml.safe_dump(SLIDE_SCENARIO, sort_keys=False))
    return where


REFUSED = {  # each bad bag: (what it holds, the refusal's message (topic, t_s), its field)
    "nan_position": ({"nan_position_at": 50}, ("/joint_states", 0.5), "position[slide]"),
    "inf_wrench": ({"inf_wrench_at": 30}, ("/wrench", 0.3), "wrench.force.z"),
    "nan_target": ({"nan_target": True}, ("/targets", 0.01), "position[j1]"),
    "no_frame": ({"wrench_frame": "cuff"}, ("/wrench", 0.0), "header.frame_id"),
}
NAN_POSITION_SAID = ("/joint_states at t=0.500 s (stamp 1700000000.500000000): position of 'slide' is NaN: a replay "
                     "needs every joint's position in every message: drop that message (a stretch without messages "
                     "is bridged by interpolation) or mend the value")  # (the command line's words, once)


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bags_bad_content_is_refused_at_the_message_before_anything_runs(slide, case):
    """NaN or inf in a joint state, the wrench or a target, a wrench frame the robot has not: refused (exit 2 at the
    command line) at the bag, topic and stamp, with the field and the fix; no output folder left (was: an internal
    error in outcomes.sparc with a half-written folder, MuJoCo diverging, a refusal located in the generated
    replayed_session.yaml)."""
    faults, (topic, t_s), field = REFUSED[case]
    bag = write_session(slide / case, **faults)
    out = slide / f"{case}-out"
    with pytest.raises(BagError) as refused:
        replay_bag(bag, slide / "slide2.yaml", out_dir=out)
    where = refused.value.where
    assert (refused.value.bag, where.topic, where.t_s, refused.value.field) == (str(bag), topic, pytest.approx(t_s),
                                                                              field)
    assert where.stamp_ns == 1_700_000_000_000_000_000 + round(t_s * 1e9)  # (the message's own stamp)
    assert not out.exists()
    if case == "nan_position":  # (the command line: exit 2, what it says in full once, no folder)
        done = cli("replay", bag, "--scenario", slide / "slide2.yaml", "--out", out)
        assert (done.returncode, done.stderr, done.stdout) == (2, f"{bag}: {NAN_POSITION_SAID}\n", "") and \
            not out.exists()


def test_what_the_replay_does_without_is_said_first_and_its_largest_deviation_last(slide, monkeypatch):
    """A joint the robot lacks (a gripper) and a NaN effort are said before the replay runs (the joint not
    replayed, the efforts not used); after the table, the replay's largest deviation from the recorded joints: the
    revolute one in degrees, the slide in metres, each with its time. The bag's messages are deserialised once: the
    recorded-wrench patient the replay builds takes its joint states and wrench from the replay's own read (it read
    the bag again: a third of an 8-s session's replay)."""
    from rosbags.highlevel import AnyReader

    deserialise, read = AnyReader.deserialize, []

    def counted(reader, data, msgtype):
        read.append(msgtype)
        return deserialise(reader, data, msgtype)

    monkeypatch.setattr(AnyReader, "deserialize", counted)
    bag = write_session(slide / "extra", extra_joint="gripper", nan_effort_at=20)
    done = cli("replay", bag, "--scenario", slide / "slide2.yaml", "--out", slide / "extra-out")
    assert done.returncode == 0, done.stderr
    assert len(read) == 100 + 100 + 2  # (its joint states, wrenches and targets, each once)
    lines = done.stdout.splitlines()
    said = [line for line in lines if line.startswith("  BAG")]
    assert said == [f"  BAG  {bag}: /joint_states at t=0.200 s (stamp 1700000000.200000000): effort of 'j1' is NaN "
                    "(1 value(s) not finite): effort not used (the session's torques are not known)",
                    f"  BAG  {bag}: /joint_states: joint(s) ['gripper'] not in robot 'slide2' (its joints: j1, slide): "
                    "not replayed", f"  BAG  {bag}: --topics reference: {NO_REFERENCE}a plan to each target{ENDS}"]
    assert lines.index(said[-1]) < next(i for i, line in enumerate(lines) if line.startswith("metric"))
    session = json.loads((slide / "extra-out" / "session.json").read_text())
    assert session["said"] == [s.removeprefix("  BAG  ") for s in said]
    (deviation,) = [line for line in lines if line.startswith("  DEVIATION")]
    arm, sliding = session["deviation"]
    assert (arm["joint"], arm["unit"], sliding["joint"], sliding["unit"]) == ("j1", "deg", "slide", "m")
    assert deviation == ("  DEVIATION  the replay's largest from the recorded joints: "
                         f"j1 by {arm['value']:.3g}° at t = {arm['t_s']:.3f} s; "
                         f"slide by {sliding['value']:.3g} m at t = {sliding['t_s']:.3f} s")
    assert 0 < arm["value"] < 20 and 0 < sliding["value"] < 0.08  # (a made-up session: not what the controller does)


# -- one plan through via points: an SO-101 session (multi-cubic A → B → C → D, 1.5 s a segment; 4.7 s at 500 Hz) --

SO101 = {
    "name": "so101-reach",
    "robot": {"type": "urdf", "file": "package://example-robot-data/robots/so_arm_description/urdf/so101.urdf",
              "ee_frame": "gripper_frame_link", "base": {"position": [0, 0, 0.5]}},
    "planner": {"type": "multi-cubic", "segment_durations": [1.5, 1.5, 1.5]},
    "controller": {"type": "joint-pd", "gains": "auto", "feedforward": "inverse-dynamics"},
    "task": {"targets": [{"name": "A", "joints_deg": [0, 0, 0, 0, 0, 0]},
                         {"name": "B", "joints_deg": [30, -30, 45, 30, 0, 20]},
                         {"name": "C", "position": [0.2, 0.0, 0.15]}, {"name": "D", "same_as": "A"}]},
    "duration": 4.7, "rates": {"control_hz": 500}}


def test_a_plan_through_via_points_replays_as_that_plan(tmp_path):
    """The SO-101's run, replayed from its own bag as the README says (no --topics: its bag has no person's wrench,
    said), is the run again: the targets shown while the reference moved are one plan through them, its last
    movement ending where the reference stopped (4.5 s, not the run's 4.7 s) — within 1e-6° (measured 6e-14°; was
    23° in a 5-s run: a replan stopping at each target, the last stretched to the run's end). Without the reference
    (a ROS user's bag) the measured joints' speed finds the same plan, but not its end: stretched, said (a 5-s run's
    replay: 20.9° off). A wrench topic named and missing is still refused. The run folder's replay says its
    deviation from the run's own bag, or why it is not known."""
    from rehabkit.cli.replay import _run_deviation
    from rehabkit.ros.replay.bag_plans import session_plans
    from rehabkit.ros.replay.bag_scenario import plans_said, shown_targets
    from rehabkit.ros.replay.session_bag import read_session

    (tmp_path / "so101.yaml").write_text(yaml.safe_dump(SO101, sort_keys=False))
    run = run_scenario(tmp_path / "so101.yaml", {"ros": {"bag": True}}, out_dir=tmp_path / "run")
    bag = tmp_path / "run" / "run.mcap"
    done = cli("replay", bag, "--scenario", tmp_path / "so101.yaml", "--out", tmp_path / "replay")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line for line in lines if line.startswith("  BAG")] == [
        f"  BAG  {bag}: --topics wrench: no topic /wrench, nor another geometry_msgs/msg/WrenchStamped: no person's "
        "wrench recorded; replayed without one (the scenario's own patient, if it has one; name their wrench's topic: "
        "--topics wrench=TOPIC)"]
    task = yaml.safe_load((tmp_path / "replay" / "replayed_session.yaml").read_text())["task"]
    assert (task["sequence"], task["events"]) == (["start", "shown_1", "shown_2", "shown_3"], [])
    replayed = load_scenario(tmp_path / "replay" / "replayed_session.yaml").model
    assert replayed.planner.segment_durations == [1.5, 1.5, 1.5] and replayed.patient is None
    (deviation,) = json.loads((tmp_path / "replay" / "session.json").read_text())["deviation"]
    assert deviation["value"] < 1e-6 and f"by {deviation['value']:.3g}°" in lines[-2]
    # a ROS user's bag: no reference
    session = read_session(bag, {"reference": ""})
    (plan,) = session_plans(session, shown_targets(session))
    assert (plan.first, plan.last, plan.t, plan.end_known) == (0, 2, 0.0, False)
    assert plan.durations == pytest.approx([1.5, 1.5, 1.7], abs=1e-9)
    assert [str(r) for r in plans_said(session, timed=True)] == [
        f"{bag}: --topics reference: {NO_REFERENCE}one plan through shown_1..shown_3{ENDS}"]
    named = cli("replay", bag, "--scenario", tmp_path / "so101.yaml", "--topics", "wrench=/wrench")
    assert named.returncode == 2 and at_bag(named.stderr) == [(str(bag), "wrench")], named.stderr
    # the run folder's replay: the scenario again (its first second), against the joints its bag kept
    again = cli("replay", tmp_path / "run", "--set", "duration=1", "--set", "ros.bag=false", "--out",
                tmp_path / "again")
    assert again.returncode == 0, again.stderr
    (line,) = [line for line in again.stdout.splitlines() if line.startswith("  DEVIATION")]
    assert line.startswith(f"  DEVIATION  the replay's largest from the run's joints ({bag}): ")
    assert float(line.split(" by ")[1].split("°")[0]) < 1e-6 and run.metrics["reaches_completed"] == 3
    assert _run_deviation(tmp_path / "replay", None) == (f"not known: {tmp_path / 'replay'} holds no run.mcap (the "
                                                         "run's joints are kept with rehabkit run --bag)")
