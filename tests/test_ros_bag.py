"""Runs as ROS 2 bags: written as the run goes (mcap + rosbags' CDR), read back here by an independent reader
(rosbags), checked against the run's trace, its summary and the robot itself."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from rehabkit.api import run_scenario
from tests.conftest import ROOT
from tests.test_cli import cli

HIT = ROOT / "scenarios" / "hit_roundtrip.yaml"


def read(bag: Path) -> tuple[dict, dict]:
    """Each topic's type and messages (deserialised), as rosbags reads the file."""
    types, messages = {}, {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        for c in r.connections:
            types[c.topic] = (c.msgtype, c.msgcount)
        for c, stamp, raw in r.messages():
            messages.setdefault(c.topic, []).append((stamp, r.deserialize(raw, c.msgtype)))
    return types, messages


# the HIT round trip's four legs (both round trips: two posture goals, two pose goals) at 1 s a leg, not 2: every
# topic and kind of message the 8.5-s run's bag has, in half the steps (at twice the speed, within HIT's limits:
# no safety event, so no /rosout)
BOTH_ROUND_TRIPS_FASTER = {"ros": {"bag": True}, "duration": 4.5, "planner.segment_durations": [1.0, 1.0, 1.0, 1.0]}


@pytest.fixture(scope="module")
def hit_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("hit")
    result = run_scenario(HIT, BOTH_ROUND_TRIPS_FASTER, out_dir=out)
    assert result.summary["safety"]["events"] == []
    return result, *read(out / "run.mcap")


def test_the_hit_round_trip_as_a_bag_holds_the_trace_exactly(hit_bag):
    result, types, messages = hit_bag
    n = len(result.trace.t)
    assert types == {"/robot_description": ("std_msgs/msg/String", 1), "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
                     "/joint_states": ("sensor_msgs/msg/JointState", n),
                     "/reference/joint_states": ("sensor_msgs/msg/JointState", n),
                     "/tf": ("tf2_msgs/msg/TFMessage", n // 10),  # (the log's 100 Hz)
                     # each leg's goal as it begins: B with the hand's orientation (A's), A as its posture
                     "/targets/pose": ("geometry_msgs/msg/PoseStamped", 2),
                     "/targets/joint_states": ("sensor_msgs/msg/JointState", 2),
                     # the encoders, as a driver publishes joint angles (500 Hz, with their resolution)
                     "/sensors/encoders/joint_states": ("sensor_msgs/msg/JointState", n // 2)}
    said = result.summary["bag"]["topics"]  # (the summary says what the bag holds)
    assert {t: (v["type"], v["messages"]) for t, v in said.items()} == types
    states = [m for _, m in messages["/joint_states"]]
    assert [list(states[0].name)] == [list(result.summary["per_joint"])]
    for column, field in ((result.trace.q, "position"), (result.trace.qd, "velocity"), (result.trace.tau, "effort")):
        assert np.abs(np.array([getattr(m, field) for m in states]) - column).max() <= 1e-12
    ref = np.array([m.position for _, m in messages["/reference/joint_states"]])
    assert np.abs(ref - result.trace.q_ref).max() <= 1e-12
    stamps = np.array([s for s, _ in messages["/joint_states"]], np.int64)  # (log time, ns: one control period apart)
    assert set(np.diff(stamps)) == {1_000_000}


def test_the_robot_description_is_the_robot(hit_bag):
    """HIT's URDF, made from its model: Pinocchio builds the same robot from it (forward kinematics over 1,000
    random postures, masses, gravity torques); /tf, composed from world, is the robot's own forward kinematics."""
    result, _, messages = hit_bag
    from rehabkit_plugins.robots.hit import HitConfig, HitRobot

    robot = HitRobot(HitConfig()).model
    mine, theirs = robot.pin_model, pin.buildModelFromXML(messages["/robot_description"][0][1].data)
    a, b = mine.createData(), theirs.createData()
    rng = np.random.default_rng(0)
    worst = 0.0
    for q in rng.uniform(robot.limits.lower, robot.limits.upper, (1000, robot.dof)):
        pin.forwardKinematics(mine, a, q)
        pin.forwardKinematics(theirs, b, q)
        worst = max(worst, max(np.abs(a.oMi[j].homogeneous - b.oMi[j].homogeneous).max() for j in range(1, 7)))
        assert np.abs(pin.computeGeneralizedGravity(mine, a, q) - pin.computeGeneralizedGravity(theirs, b, q)).max() \
            < 1e-9
    assert worst < 1e-12 and sum(i.mass for i in mine.inertias) == pytest.approx(sum(i.mass for i in theirs.inertias))
    k = 300  # a logged step: /tf's links chained from the world, against the robot's own frames
    tf = {t.child_frame_id: t for t in messages["/tf"][k][1].transforms}
    (base,) = [t for t in messages["/tf_static"][0][1].transforms if t.header.frame_id == "world"]

    def pose(t) -> np.ndarray:
        r, p = t.transform.rotation, t.transform.translation
        m = np.eye(4)
        m[:3, :3] = pin.Quaternion(r.w, r.x, r.y, r.z).toRotationMatrix()
        m[:3, 3] = (p.x, p.y, p.z)
        return m

    chain, link = pose(base), "wrist_2_link"
    path = []
    while link in tf:
        path.append(tf[link])
        link = tf[link].header.frame_id
    for t in reversed(path):
        chain = chain @ pose(t)
    pin.forwardKinematics(mine, a, result.trace.q[10 * k])
    np.testing.assert_allclose(chain, robot.base_pose @ a.oMi[6].homogeneous, atol=1e-12)


def test_a_urdf_robot_carries_its_own_file_and_safety_events_go_to_rosout(tmp_path):
    """The README's URDF arm: /robot_description is its file as written. HIT's e-stop skill: the stop on /rosout as
    an ERROR, at its time."""
    done = cli("run", "urdf_arm4.yaml", "--bag", "--set", "duration=1", "--out", str(tmp_path / "arm"),
               cwd=ROOT / "examples" / "robots")
    assert done.returncode in (0, 1), done.stderr  # (a 1 s run leaves its expectations unmet)
    _, messages = read(tmp_path / "arm" / "run.mcap")
    assert messages["/robot_description"][0][1].data == (ROOT / "examples" / "robots" / "arm4.urdf").read_text()
    stop = run_scenario(ROOT / "scenarios" / "safety" / "hit_estop.yaml", {"ros": {"bag": True}},
                        out_dir=tmp_path / "estop")
    _, messages = read(tmp_path / "estop" / "run.mcap")
    logs = [(s, m) for s, m in messages["/rosout"] if m.level == 40]  # (the stop, then the brakes it engaged)
    (event,) = stop.summary["safety"]["events"]
    assert [m.msg for _, m in logs] == [f"SAFETY {event['message']}", "SAFETY t=1.128s: torque off; holding brakes "
                                        "engaged"] and logs[0][1].name == "rehabkit"
    first = messages["/joint_states"][0][0]
    assert logs[0][0] - first == round(event["t"] * 1e9)


def test_the_readmes_ros_commands_run_as_written(tmp_path):
    """"Working with ROS 2 tools": the run with ``--bag``, then the README's reading of its joint states."""
    import contextlib
    import io
    import re

    section = (ROOT / "README.md").read_text().split("## Working with ROS 2 tools")[1].split("\n## ")[0]
    (command,), code = re.findall(r"```bash\n(.*?)\n```", section, re.S), re.findall(r"```python\n(.*?)```", section,
                                                                                       re.S)[0]
    (tmp_path / "scenarios").symlink_to(ROOT / "scenarios")
    done = cli(*command.split()[1:], cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    shown = io.StringIO()
    here = Path.cwd()
    try:
        import os

        os.chdir(tmp_path)
        with contextlib.redirect_stdout(shown):
            exec(compile(code, "README.md (reading a bag)", "exec"), {})
    finally:
        os.chdir(here)
    assert shown.getvalue().startswith("['shoulder_1', 'shoulder_2', 'elbow_1', 'elbow_2', 'wrist_1', 'wrist_2'] [")


def test_sensor_readings_go_to_their_ros_messages(tmp_path):
    """hit-force: the six-axis sensor's readings as geometry_msgs/WrenchStamped in its mount's frame, each the
    interaction force the safety layer checked (the trace's magnitude, to 1e-9 N: the loop samples an interaction
    sensor every step, and a reading at step k gives the sample of step k - 1, the latest there is).
    L-Exos reaching, the ball shown at 0.5 s, to 1.1 s: the overhead camera's frames as sensor_msgs/Image (rgb8), the
    ball's red blob in them where the camera's own pixel reading says (within 2 px), its sighting as a PointStamped in
    the base frame."""
    force = run_scenario(ROOT / "scenarios" / "safety" / "hit_force.yaml", {"ros": {"bag": True}},
                         out_dir=tmp_path / "ft")
    types, messages = read(tmp_path / "ft" / "run.mcap")
    assert types["/sensors/ft/wrench"] == ("geometry_msgs/msg/WrenchStamped", 181)
    assert types["/sensors/ft/raw_force_n"][0] == "std_msgs/msg/Float64MultiArray"
    first = messages["/joint_states"][0][0]
    tr = force.trace
    checked = 0
    for stamp, m in messages["/sensors/ft/wrench"]:
        assert m.header.frame_id == "wrist_2_link"
        k = round((stamp - first) / 1e6)
        f = m.wrench.force
        if 0 < k <= len(tr.t):
            assert tr.f_h[k - 1] == pytest.approx(np.linalg.norm([f.x, f.y, f.z]), abs=1e-9)
            checked += 1
    assert checked == 180 and tr.f_h.max() > 29.0  # (the push reached the limit)
    # (the ball shown at Target 1 at 0.5 s, not 4 s: the same six frames with the ball in them, 35 fewer without)
    run_scenario(ROOT / "scenarios" / "lexos_reaching.yaml", {"ros": {"bag": True}, "duration": 1.1,
                                                               "task.events.0.at": 0.5}, out_dir=tmp_path / "cam")
    types, messages = read(tmp_path / "cam" / "run.mcap")
    assert types["/sensors/camera/image"] == ("sensor_msgs/msg/Image", 11)
    pixels = {s: m.data for s, m in messages["/sensors/camera/pixel"]}
    seen = 0
    for stamp, m in messages["/sensors/camera/image"]:
        assert (m.encoding, m.height, m.width, m.step) == ("rgb8", 480, 640, 1920)
        if stamp not in pixels:
            continue
        img = np.frombuffer(m.data, np.uint8).reshape(480, 640, 3).astype(int)
        red = (img[..., 0] > 150) & (img[..., 1] < 80) & (img[..., 2] < 80)
        v, u = np.argwhere(red).mean(axis=0)
        assert np.hypot(u - pixels[stamp][0], v - pixels[stamp][1]) < 2.0
        seen += 1
    assert seen >= 5
    sighted = messages["/sensors/camera/target_position"][-1][1]
    assert sighted.header.frame_id == "base"  # (the L-Exos base link: its model's root body)
    ball = np.array([0.82, 0.33, 0.77]) - np.array([0, 0, 1.2])  # Target 1 in the base frame (shoulder at 1.2 m)
    assert np.linalg.norm([sighted.point.x - ball[0], sighted.point.y - ball[1], sighted.point.z - ball[2]]) < 0.025


def test_a_sweeps_runs_each_write_their_bag(tmp_path):
    """``rehabkit sweep --bag``: every run keeps its folder (the run_dir column) with its own bag, whose joint
    states are that run's (the softer gains track worse: their bags differ)."""
    import pyarrow.parquet as pq
    import yaml

    done = cli("sweep", ROOT / "examples" / "ros_session" / "arm4_session.yaml", "--grid",
               "controller.bandwidth_hz=4,8", "--set", "duration=1.5", "--bag", "--serial", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    rows = pq.read_table(tmp_path / "results.parquet").to_pylist()
    finals = []
    for row in rows:
        types, messages = read(tmp_path / row["run_dir"] / "run.mcap")
        assert types["/joint_states"] == ("sensor_msgs/msg/JointState", 1500)
        # (the start posture, then the first position target)
        assert types["/wrench"][1] == 1500 and types["/targets/joint_states"][1] == types["/targets"][1] == 1
        finals.append(np.array(messages["/joint_states"][-1][1].position))
        ran = yaml.safe_load((tmp_path / row["run_dir"] / "scenario.yaml").read_text())
        assert ran["controller"]["bandwidth_hz"] == row["controller.bandwidth_hz"]  # (a numeric grid: its numbers)
    assert np.abs(finals[0] - finals[1]).max() > 1e-3


def test_a_one_joint_robots_wrench_is_the_least_one_with_its_torque():
    """A one-joint robot's Jacobian comes from Pinocchio as a vector; the bag's /wrench is still the least wrench
    whose joint torque is the person's (the elbow dynamometer's bag failed on it)."""
    from rehabkit.models.hand_force import least_wrenches

    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "elbow")
    model.appendBodyToJoint(joint, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
    hand = model.addFrame(pin.Frame("hand", joint, 0, pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.0])),
                                    pin.FrameType.OP_FRAME))
    w = least_wrenches(model, np.array([[0.2], [0.4]]), np.array([1.5, -3.0]), hand)
    # τ = 1.5 N·m about z, 0.3 m from the axis: the least wrench splits it between a force along y and a moment
    # about z, in the ratio of the Jacobian's column (0.3, 1)
    assert w.shape == (2, 6)
    assert w[0, 1] == pytest.approx(1.5 * 0.3 / (0.3**2 + 1)) and w[0, 5] == pytest.approx(1.5 / (0.3**2 + 1))
    assert w[1, 5] == pytest.approx(-3.0 / (0.3**2 + 1))


def test_a_bag_of_a_robot_with_closed_loops_is_refused_by_validate_at_its_setting():
    from tests.located import refusal

    (d,) = refusal(ROOT / "scenarios" / "capaman_obstacle.yaml", "ros.bag=true").diagnostics
    assert (d.path, d.fix) == ("ros.bag", "run it without --bag / ros.bag")


def test_a_joint_encoders_revolute_and_prismatic_joints_are_one_joint_state_in_si():
    """A slide's position_m beside the revolute joints' position_rad: one JointState, radians and metres as ROS has
    them (the slide went out as a Float64MultiArray)."""
    from rehabkit.ros.bag_sensors import reading_messages

    names = {"position_rad": ["j1"], "position_m": ["slide"]}
    out = list(reading_messages("enc", {"position_rad": np.array([0.5]), "position_m": np.array([0.125])},
                                {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": ""}, "l1", lambda k, n: names[k]))
    assert [(topic, kind) for topic, kind, _ in out] == [("/sensors/enc/joint_states", "sensor_msgs/JointState")]
    assert out[0][2]["name"] == ["j1", "slide"] and out[0][2]["position"] == [0.5, 0.125]


def test_a_coupled_joints_urdf_is_a_mimic_joint_that_moves_as_the_model_does():
    """The ARM's mirrored finger (a joint coupled to the gripper's: Pinocchio's Mimic) is a URDF <mimic> joint:
    Pinocchio, told to read mimics, builds the same robot from it — every body where the model has it at random
    postures. (It had no URDF form: ``--bag`` on the ARM scenario ended in an internal error.)"""
    from rehabkit_plugins.robots.arm import ArmConfig, ArmRobot

    from rehabkit.ros.description import urdf_from_model

    robot = ArmRobot(ArmConfig()).model
    mine = robot.pin_model
    urdf = urdf_from_model(mine, robot.name, robot.limits)
    assert '<mimic joint="gripper" multiplier="1" offset="0"/>' in urdf
    theirs = pin.buildModelFromXML(urdf, mimic=True)
    assert theirs.nq == mine.nq == robot.dof
    a, b = mine.createData(), theirs.createData()
    for q in np.random.default_rng(1).uniform(robot.limits.lower, robot.limits.upper, (50, robot.dof)):
        pin.forwardKinematics(mine, a, q)
        pin.forwardKinematics(theirs, b, q)
        for name in ("gripper", "gripper_mirror", "j6"):
            i, j = mine.getJointId(name), theirs.getJointId(name)
            np.testing.assert_allclose(b.oMi[j].homogeneous, a.oMi[i].homogeneous, atol=1e-12)
