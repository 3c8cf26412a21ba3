"""Robots from ROS description packages as they ship: a package of our own (xacro with an argument, package://
meshes, COLLADA converted) and UR5 from example-robot-data (package:// URIs found through AMENT_PREFIX_PATH).
Pinocchio and MuJoCo build the robot from the same resolved description: their forward kinematics and masses
agree."""

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from rehabkit.api import run_scenario
from tests.conftest import ROOT
from tests.located import located
from tests.test_cli import cli

DATA = ROOT / "tests" / "data"
ERD = Path(__import__("cmeel").__file__).parent.parent / "cmeel.prefix"  # example-robot-data's install prefix


def _robot(section: dict, folder: Path):
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry

    info = default_registry().get("robot", section["type"])
    return info.factory(info.config.model_validate(section), Context(folder, np.random.default_rng(0), 0.001))


def _agreement(robot, postures: int = 1000) -> tuple[float, float]:
    """Largest end-effector distance between Pinocchio's and MuJoCo's forward kinematics over random postures [m],
    and the difference of their total masses [kg]."""
    from rehabkit.hardware.plant import MujocoPlant

    plant = MujocoPlant(robot)
    lim = robot.model.limits
    qs = np.random.default_rng(1).uniform(lim.lower, lim.upper, (postures, robot.model.dof))
    site = plant.model.site(robot.model.ee_site).id
    worst = 0.0
    for q in qs:
        plant.data.qpos[plant._q] = q
        mujoco.mj_kinematics(plant.model, plant.data)
        worst = max(worst, float(np.linalg.norm(plant.data.site_xpos[site] - robot.ee_world(q[None])[0])))
    pin_mass = sum(i.mass for i in robot.model.pin_model.inertias)
    mj_mass = float(plant.model.body_mass[1:].sum())
    return worst, abs(pin_mass - mj_mass)


def test_a_description_package_with_xacro_and_collada_runs_and_both_engines_agree(tmp_path, monkeypatch):
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    section = yaml.safe_load((DATA / "rehab_arm.yaml").read_text())["robot"]
    robot = _robot(section, DATA)
    assert robot.model.joint_names == ["shoulder", "elbow"]
    np.testing.assert_allclose(robot.ee_world(np.zeros((1, 2)))[0], [0, 0, 0.1 + 0.32 + 0.25], atol=1e-12)  # (arg)
    distance, mass = _agreement(robot)
    assert distance < 1e-9 and mass < 1e-9
    stl = list((tmp_path / "cache" / "descriptions" / "meshes").glob("link-*.stl"))
    assert len(stl) == 1  # (converted once, by content)
    made = stl[0].stat().st_mtime_ns
    _robot(section, DATA)  # a second load converts nothing
    assert stl[0].stat().st_mtime_ns == made
    done = cli("run", "rehab_arm.yaml", "--out", str(tmp_path / "run"), cwd=DATA)
    assert done.returncode == 0, done.stderr
    # the hand's OBJ (with its material library) is its collision mesh as it is, in its material's colour; what only
    # the looks need is said once: the base's visual-only STL, the glove's texture
    model = mujoco.MjModel.from_xml_string(robot.model.mjcf)
    hand = model.mesh("hand")
    assert (hand.vertnum[0], hand.facenum[0]) == (8, 12)
    assert np.allclose(model.geom_rgba[model.body("hand").geomadr[0]], [0.85, 0.72, 0.62, 1.0])
    assert model.body_mass[model.body("hand").id] == pytest.approx(0.3)
    notes = [n["text"] for n in json.loads((tmp_path / "run" / "summary.json").read_text())["notes"]]
    assert notes == ["arm.urdf: MuJoCo simulates and draws each link by its collision geometry; link(s) base_link "
                     "have a visual and no collision geometry: not drawn; the texture of material(s) glove is not "
                     "shown (their colour is)"]


def test_ur5_from_example_robot_data_as_its_package_ships_it(tmp_path, monkeypatch):
    """UR5's URDF exactly as example-robot-data installs it (package:// URIs, COLLADA visuals, STL collisions): its
    package found where pip put it (cmeel's prefix of this interpreter) with no variable set — a new user had to find
    that folder with `pip show -f` and name it in AMENT_PREFIX_PATH — and both engines agree. A package that is
    nowhere is refused at the file's line, saying where it was looked for."""
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    urdf = ERD / "share" / "example-robot-data" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
    scenario = tmp_path / "ur5.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": "ur5", "robot": {"type": "urdf", "file": str(urdf), "ee_frame": "tool0"},
        "planner": {"type": "multi-cubic", "segment_durations": [2.0]},
        "controller": {"type": "joint-pd", "kp": [200, 200, 100, 50, 20, 20], "kd": [20, 20, 10, 5, 2, 2],
                       "feedforward": "inverse-dynamics"},
        "task": {"targets": [{"name": "A", "joints_deg": [0, -90, 90, -90, -90, 0]},
                             {"name": "B", "joints_deg": [20, -80, 80, -90, -90, 10]}]},
        "duration": 2.5, "expect": {"final_joint_error_deg": {"lt": 0.5}}}))
    assert cli("validate", str(scenario), cwd=tmp_path).returncode == 0
    nowhere = tmp_path / "nowhere.urdf"
    nowhere.write_text(urdf.read_text().replace("package://example-robot-data/", "package://no_such_package/"))
    (tmp_path / "nowhere.yaml").write_text(scenario.read_text().replace(str(urdf), str(nowhere)))
    refused = cli("validate", str(tmp_path / "nowhere.yaml"), cwd=tmp_path)
    line = next(i for i, x in enumerate(scenario.read_text().splitlines(), 1) if x.strip().startswith("file:"))
    assert (refused.returncode, [(f, n, at) for f, n, _, at in located(refused.stderr)]) == (
        2, [("nowhere.yaml", line, "robot.file")]), refused.stderr
    from rehabkit.models.files.ros_package import DescriptionError, prepared

    with pytest.raises(DescriptionError) as nowhere_found:  # what it says there: where it looked
        prepared(nowhere)
    assert nowhere_found.value.uri.startswith("package://no_such_package/")
    assert any(Path(p).parent.name == "cmeel.prefix" for p in nowhere_found.value.looked)  # (pip's prefixes too)
    robot = _robot({"type": "urdf", "file": str(urdf), "ee_frame": "tool0"}, tmp_path)
    assert robot.model.dof == 6
    distance, mass = _agreement(robot)
    assert distance < 1e-9 and mass < 1e-6
    result = run_scenario(scenario)
    assert result.passed, result.failures


def test_a_mesh_the_package_does_not_have_is_said_with_the_file(tmp_path):
    from rehabkit.models.files.ros_package import DescriptionError, resolve_uri

    with pytest.raises(DescriptionError) as missing:
        resolve_uri("package://rehab_arm_description/meshes/elbow.dae", tmp_path, [DATA])
    assert missing.value.uri == "package://rehab_arm_description/meshes/elbow.dae"
    assert missing.value.file == DATA / "rehab_arm_description" / "meshes" / "elbow.dae"  # (the file)


def test_the_readmes_package_example_is_the_tested_one():
    readme = (ROOT / "README.md").read_text().split("## Your robot from its ROS package")[1].split("\n## ")[0]
    block = yaml.safe_load(readme.split("```yaml\n")[1].split("```")[0])
    assert block["robot"] == yaml.safe_load((DATA / "rehab_arm.yaml").read_text())["robot"]


def test_an_end_effector_on_a_massless_fixed_link_is_where_both_engines_say(tmp_path, monkeypatch):
    """Panda's ``panda_hand_tcp``: a massless link on a fixed joint 0.1034 m past the hand. Pinocchio's MJCF parser
    put a site on such a body 0.107 m off; the end effector is Pinocchio's frame of the body itself."""
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(ERD))
    urdf = ERD / "share" / "example-robot-data" / "robots" / "panda_description" / "urdf" / "panda.urdf"
    robot = _robot({"type": "urdf", "file": str(urdf), "ee_frame": "panda_hand_tcp"}, tmp_path)
    distance, mass = _agreement(robot, 200)
    assert robot.model.dof == 8 and distance < 1e-9 and mass < 1e-9  # (the mimic finger not driven: next test)


def test_a_mimic_joint_follows_its_leader_and_is_not_driven(tmp_path, monkeypatch):
    """Panda's second finger mimics the first (<mimic>, a joint equality in MuJoCo): the robot drives eight joints,
    the ninth follows; in the simulation it moves with its leader."""
    from rehabkit.hardware.plant import MujocoPlant

    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(ERD))
    urdf = ERD / "share" / "example-robot-data" / "robots" / "panda_description" / "urdf" / "panda.urdf"
    robot = _robot({"type": "urdf", "file": str(urdf), "ee_frame": "panda_hand_tcp"}, tmp_path)
    assert robot.model.dof == 8 and robot.model.passive_joints == ["panda_finger_joint2"]
    assert robot.model.pin_model.nq == 8
    plant = MujocoPlant(robot)
    q0 = (robot.model.limits.lower + robot.model.limits.upper) / 2
    plant.reset(q0)
    tau = robot.gravity_torque(q0)
    tau[-1] += 0.05  # the first finger pushed (15 g, its twin's weight on it through the coupling: it moves)
    for _ in range(50):
        plant.apply(tau)
        plant.advance()
    leader = plant.read()[0][-1]
    follower = plant.data.qpos[plant.model.jnt_qposadr[plant.model.joint("panda_finger_joint2").id]]
    assert abs(leader - q0[-1]) > 0.001 and abs(follower - leader) < 1e-4


SOLO_STANDING = [0.1, 0.8, -1.6, -0.1, 0.8, -1.6, 0.1, -0.8, 1.6, -0.1, -0.8, 1.6]  # its SRDF's "standing"


def test_a_floating_quadruped_stands_on_its_feet(tmp_path, monkeypatch):
    """Solo12 as its package ships it, with a floating base (``floating: true``, its four feet the support): MuJoCo
    simulates the free root (Pinocchio's model, root locked, agrees on the legs' kinematics), the robot holds its
    SRDF's standing posture on the floor, level, touching it with its feet only, its base where the legs' forward
    kinematics and the foot mesh's lowest point put it (within 2 mm: the contacts' softness)."""
    import pinocchio as pin
    import trimesh

    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(ERD))
    solo = ERD / "share" / "example-robot-data" / "robots" / "solo_description"
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    section = {"type": "urdf", "file": str(solo / "robots" / "solo12.urdf"), "ee_frame": "FL_FOOT", "floating": True,
               "feet": feet, "base": {"position": [0, 0, 0.235]}}
    robot = _robot(section, tmp_path)
    assert robot.model.floating and robot.model.passive_joints == ["root"] and robot.model.dof == 12
    assert robot.model.support_geoms == [f"{f}_foot_0" for f in feet]
    distance, mass = _agreement(robot)
    assert distance < 1e-9 and mass < 1e-9
    scenario = tmp_path / "solo.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": "solo12-standing", "robot": section, "planner": {"type": "multi-cubic", "segment_durations": [1.0]},
        "controller": {"type": "joint-pd", "kp": 20, "kd": 0.3},
        "task": {"targets": [{"name": "stand", "joints_rad": SOLO_STANDING}]}, "duration": 2.0,
        "ros": {"bag": True}}))
    runner = Runner(load_scenario(scenario), out_dir=tmp_path / "run")
    result = runner.run()
    assert result.metrics["contact_steps"] == 0  # (the feet on the floor are support)
    position, quaternion, _, _ = runner.backend.base_state()
    assert np.degrees(2 * np.arccos(min(1.0, abs(quaternion[0])))) < 0.1  # level
    model = robot.model.pin_model
    data = model.createData()
    pin.framesForwardKinematics(model, data, result.trace.q[-1])
    lowest = trimesh.load(solo / "meshes" / "stl" / "with_foot" / "solo_foot.stl").bounds[0][2]
    below = max(data.oMf[model.getFrameId(f)].translation[2] for f in feet) + lowest
    assert position[2] == pytest.approx(-below, abs=0.002)
    assert np.degrees(np.abs(result.trace.q[-1] - SOLO_STANDING)).max() < 3.0
    # its bag: every link of its own URDF in the tf tree (the feet, fixed links, on /tf_static as the URDF places
    # them), and the floating base where the simulation has it, at the log rate
    import xml.etree.ElementTree as ET

    from tests.test_ros_bag import read

    _, messages = read(tmp_path / "run" / "run.mcap")
    own = {link.get("name") for link in ET.fromstring(messages["/robot_description"][0][1].data).iter("link")}
    static = {t.child_frame_id: t for _, m in messages["/tf_static"] for t in m.transforms}
    moving = {t.child_frame_id: t for t in messages["/tf"][-1][1].transforms}
    assert own <= set(static) | set(moving)
    foot = static["FL_FOOT"]
    assert foot.header.frame_id == "FL_LOWER_LEG"
    offset = foot.transform.translation
    assert (offset.x, offset.y, offset.z) == pytest.approx((0.0, 0.008, -0.16), abs=1e-12)  # (its URDF joint's)
    root = moving["base_link"]  # (the URDF's root link, under the scene's world)
    assert root.header.frame_id == "world"  # (its last logged pose, 10 ms before the end: settled)
    assert root.transform.translation.z == pytest.approx(position[2], abs=1e-4)


def test_the_engines_are_checked_against_each_other_at_load(tmp_path):
    """A robot from a file is refused at load when Pinocchio's model and MuJoCo's disagree: here MuJoCo's model is
    of the arm with its upper arm 1 cm longer and 0.1 kg heavier than the robot Pinocchio was built from — the check
    finds the end effector up to 1 cm apart and the mass 0.1 kg off; the file's own two engines agree."""
    from rehabkit.models.files.engine_check import engine_agreement
    from rehabkit.models.files.mjcf_import import _load_spec

    urdf = ROOT / "examples" / "robots" / "arm4.urdf"
    robot = _robot({"type": "urdf", "file": str(urdf), "ee_frame": "tip"}, tmp_path)
    same = engine_agreement(_load_spec(urdf).compile(), robot.model, "tip")
    assert same.agree and same.distance_m < 1e-12 and same.mass_pinocchio == pytest.approx(same.mass_mujoco)
    longer = tmp_path / "arm4.urdf"
    longer.write_text(urdf.read_text().replace('<child link="forearm"/><origin xyz="0.3 0 0"/>',
                                               '<child link="forearm"/><origin xyz="0.31 0 0"/>')
                      .replace('<mass value="1.2"/>', '<mass value="1.3"/>'))
    other = engine_agreement(_load_spec(longer).compile(), robot.model, "tip")
    assert not other.agree and 0.005 < other.distance_m <= 0.01 + 1e-9  # (the 1 cm, seen from where the hand is)
    assert other.mass_mujoco - other.mass_pinocchio == pytest.approx(0.1)
    assert str(other).startswith("Pinocchio and MuJoCo read this model differently: the end effector 'tip' ")


def test_the_robot_file_itself_may_be_a_package_uri(tmp_path, monkeypatch):
    """``file: package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf`` as ROS tools take it; the
    package not found is said at robot.file, with where it looked."""
    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path / "cache"))
    uri = "package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
    (tmp_path / "ur5.yaml").write_text(yaml.safe_dump({
        "name": "ur5-by-uri", "robot": {"type": "urdf", "file": uri, "ee_frame": "tool0"},
        "planner": {"type": "multi-cubic", "segment_durations": [1.0]}, "controller": {"type": "joint-pd"},
        "task": {"targets": [{"name": "A", "joints_deg": [0, -90, 90, 0, 0, 0]},
                             {"name": "B", "joints_deg": [10, -80, 80, 0, 0, 0]}]}, "duration": 1.0}))
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    found = cli("validate", "ur5.yaml", cwd=tmp_path)  # (pip's prefix: no variable needed)
    assert found.returncode == 0, found.stderr
    (tmp_path / "lost.yaml").write_text((tmp_path / "ur5.yaml").read_text().replace("example-robot-data", "no-such"))
    lost = cli("validate", "lost.yaml", cwd=tmp_path)
    assert lost.returncode == 2
    line = next(i for i, text in enumerate((tmp_path / "lost.yaml").read_text().splitlines(), 1) if "no-such" in text)
    assert [(f, n, at) for f, n, _, at in located(lost.stderr)] == [("lost.yaml", line, "robot.file")], lost.stderr


def test_a_target_in_a_frame_fixed_to_the_base_is_taken_through_that_frames_pose(tmp_path, monkeypatch):
    """UR5's ``base`` link is its ``base_link`` turned half a turn about z (ROS-Industrial's convention): a target a
    session showed in ``base`` is replayed where that frame puts it, not read as if it were in ``base_link``."""
    from rehabkit.ros.replay.bag_replay import base_frames
    from rehabkit.ros.replay.bag_scenario import _in_base
    from rehabkit.ros.replay.session_bag import SessionBag, ShownTarget

    monkeypatch.setenv("AMENT_PREFIX_PATH", str(ERD))
    urdf = ERD / "share" / "example-robot-data" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
    robot = _robot({"type": "urdf", "file": str(urdf), "ee_frame": "tool0"}, tmp_path)
    frames = base_frames(robot)
    assert {"base_link", "base"} <= set(frames)
    np.testing.assert_allclose(frames["base_link"], np.eye(4), atol=1e-12)
    bag = SessionBag.__new__(SessionBag)
    point = np.array([0.4, 0.1, 0.3])
    for frame, where in (("base", [-0.4, -0.1, 0.3]), ("base_link", point), ("", point)):
        p, rot = _in_base(bag, ShownTarget(1.0, "point", point, frame), np.eye(4), frames)
        np.testing.assert_allclose(p, where, atol=1e-12)
        assert rot is None
    pose = np.array([0.4, 0.1, 0.3, 0.0, 0.0, 0.0, 1.0])  # (x, y, z, then the quaternion x, y, z, w: no turn)
    p, rot = _in_base(bag, ShownTarget(1.0, "pose", pose, "base"), np.eye(4), frames)
    np.testing.assert_allclose(rot, np.diag([-1.0, -1.0, 1.0]), atol=1e-12)  # the frame's own half turn
    # the hand's pose there is the robot's own: tool0 at the home posture, seen from base, is where FK says
    tool = robot.fk(np.zeros(6))
    seen = np.linalg.inv(frames["base"]) @ tool
    p, _ = _in_base(bag, ShownTarget(1.0, "point", seen[:3, 3], "base"), np.eye(4), frames)
    np.testing.assert_allclose(p, tool[:3, 3], atol=1e-12)
