"""A prismatic joint in metres everywhere (issue 46), on example-robot-data's Panda as it ships (its finger slides
0-0.04 m) and on a SCARA written as a DH table (examples/robots/dh_scara.yaml, its quill slides 0-0.2 m): a posture
gives the finger in metres and the run, its bag, its outcomes, its recording's panels and its safety log say metres;
the safety envelope and the robot's limit overrides take a prismatic joint's limits in metres, m/s and N, and refuse
a degrees key on it (and a metres key on a revolute joint) at its line, with the key to write."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from tests.conftest import ROOT
from tests.test_cli import cli
from tests.test_recording_layout import _flat, read_layout, recording

PANDA = {"type": "urdf", "file": "package://example-robot-data/robots/panda_description/urdf/panda.urdf",
         "ee_frame": "panda_hand_tcp"}  # (found where pip put it: no variable)
ARM = [0, -45, 0, -135, 0, 90, 45]  # degrees
SCARA = ROOT / "examples" / "robots" / "dh_scara.yaml"


def _panda(folder: Path, **over) -> Path:
    """A short Panda scenario whose second posture gives the finger 0.02 m (the first 0.01 m), in `joints: [...]`."""
    scenario = {"name": "panda-finger", "robot": PANDA,
                "planner": {"type": "multi-cubic", "segment_durations": [0.6]},
                "controller": {"type": "joint-pd", "gains": "auto", "feedforward": "inverse-dynamics"},
                "task": {"targets": [{"name": "open", "joints": [*ARM, 0.01]},
                                     {"name": "grip", "joints": [*ARM, 0.02]}]},
                "safety": {"joints": {"panda_finger_joint1": {"velocity_m_s": 0.15, "force_n": 80}}},
                "ros": {"bag": True}, "duration": 1.0, **over}
    path = folder / "panda.yaml"
    scenario = {k: v for k, v in scenario.items() if v is not None}  # (None: the section left out)
    path.write_text(yaml.safe_dump(scenario, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def panda_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("panda")
    runner = Runner(load_scenario(_panda(folder)), out_dir=folder / "out")
    return runner, runner.run(), folder / "out"


def test_a_panda_finger_given_002_m_is_at_002_m_in_the_run_the_bag_and_the_outcomes(panda_run):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    runner, result, out = panda_run
    model = runner.setup.robot.model
    finger = model.joint_names.index("panda_finger_joint1")
    assert not model.revolute[finger] and model.revolute[:finger].all()
    assert result.passed, result.failures
    assert result.trace.q[-1, finger] == pytest.approx(0.02, abs=2e-4)  # (it was 0.000349 m: 0.02 read as degrees)
    with AnyReader([out / "run.mcap"], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as bag:
        (states,) = [c for c in bag.connections if c.topic == "/joint_states"]
        *_, (_, _, raw) = bag.messages(connections=[states])
        last = bag.deserialize(raw, states.msgtype)
    assert list(last.name) == model.joint_names and last.position[finger] == pytest.approx(0.02, abs=2e-4)
    m = result.metrics
    assert m["rom_m_panda_finger_joint1"] == pytest.approx(0.01, abs=3e-4) and "rom_deg_panda_finger_joint1" not in m
    assert m["final_joint_error_m"] < 2e-4 and m["joint_limit_excess_m"] == 0.0
    assert result.summary["per_joint"]["panda_finger_joint1"]["range_m"] == pytest.approx([0.01, 0.02], abs=3e-4)
    info = result.summary["metric_info"]
    assert {info[k]["unit"] for k in ("rom_m_panda_finger_joint1", "joint_limit_excess_m", "final_joint_error_m")} \
        == {"m"}


def test_the_safety_log_gives_the_finger_s_limits_in_metres_and_newtons_and_the_envelope_s_in_si(panda_run):
    _, _, out = panda_run
    limits = next(json.loads(line) for line in (out / "safety_log.jsonl").read_text().splitlines()
                  if '"kind": "limits"' in line)["joints"]
    finger = limits["panda_finger_joint1"]
    # the robot's range (0-0.04 m, was "lower_deg 0, upper_deg 2.29"); the envelope's speed and force, as written
    assert (finger["lower_m"], finger["upper_m"], finger["velocity_m_s"], finger["effort_n"]) == (0.0, 0.04, 0.15, 80.0)
    assert set(finger["narrowed_by"]) == {"velocity", "effort"} and "effort_nm" not in finger
    assert limits["panda_joint1"]["upper_deg"] == pytest.approx(166.0, abs=0.01)


def test_the_recording_shows_the_finger_in_metres_and_newtons_with_titles_that_say_so(panda_run):
    runner, result, out = panda_run
    names = runner.setup.robot.model.joint_names
    data = recording(out / "run.rrd")
    measured = data["joints/panda_finger_joint1/measured_m"]
    assert measured["SeriesLines:names"] == [["panda_finger_joint1 measured [m]"]]
    q = np.array(measured["Scalars:scalars"]).ravel()
    assert q[-1] == pytest.approx(0.02, abs=2e-4) and np.allclose(q, result.trace.q[::10, -1][: len(q)], atol=1e-12)
    assert np.allclose(data["joints/panda_finger_joint1/limits_m"]["Scalars:scalars"][0], [0.0, 0.04])
    assert "joints/panda_finger_joint1/measured_deg" not in data and "joints/panda_joint4/measured_deg" in data
    assert data["joint_force_n"]["SeriesLines:names"][0] == ["panda_finger_joint1 [N]"]
    assert data["joint_velocity_m_s"]["SeriesLines:names"][0] == ["panda_finger_joint1 [m/s]"]
    assert data["joint_torque_nm"]["SeriesLines:names"][0] == [f"{j} [N·m]" for j in names[:7]]
    flat = _flat(read_layout(out / "run.rrd")[0])
    titles = {v[1]: v[2] for v in flat if v[0] == "TimeSeries"}
    assert titles["panda_finger_joint1 [m]"] == "joints/panda_finger_joint1" and "panda_joint1 [deg]" in titles
    assert titles["joint forces [N]"] == "joint_force_n" and titles["tracking errors [m]"] == "tracking_error_m"
    assert titles["joint torques [N·m]"] == "joint_torque_nm"


def test_a_degrees_key_on_the_finger_and_a_metres_key_on_an_arm_joint_are_refused_at_their_line(tmp_path):
    path = _panda(tmp_path, safety={"joints": {"panda_finger_joint1": {"range_deg": [0, 0.03], "torque_nm": 5},
                                               "panda_joint2": {"velocity_m_s": 1.0}}})
    refused = cli("validate", path)
    lines = refused.stderr.splitlines()
    assert refused.returncode == 2 and len(lines) == 3, refused.stderr
    text = path.read_text().splitlines()
    for line, key in zip(lines, ("panda_finger_joint1.range_deg", "panda_finger_joint1.torque_nm",
                                 "panda_joint2.velocity_m_s")):
        where, rest = line.split(": ", 1)
        row, col = map(int, where.rsplit(":", 2)[1:])
        assert rest.startswith(f"safety.joints.{key}: ") and text[row - 1][col - 1:].startswith(key.split(".")[1])
    assert lines[0].endswith("panda_finger_joint1 is a prismatic joint: range_deg [deg] is for a revolute joint; "
                             "write range_m instead, in m (the robot's own: [0, 0.04] m)")
    assert lines[1].endswith("write force_n instead, in N (the robot's own: 100 N)")
    assert lines[2].endswith("panda_joint2 is a revolute joint: velocity_m_s [m/s] is for a prismatic joint; write "
                             "velocity_deg_s instead, in deg/s (the robot's own: 124.6 deg/s)")
    robot = {**PANDA, "limits": {"panda_finger_joint1": {"range_deg": [0, 0.03]}}}
    refused = cli("validate", _panda(tmp_path, robot=robot))
    assert refused.returncode == 2 and ": robot.limits.panda_finger_joint1.range_deg: " in refused.stderr
    assert "joint 'panda_finger_joint1' is prismatic (metres): range_deg is for a revolute joint; write range_m " \
           "instead" in refused.stderr
    robot["limits"] = {"panda_finger_joint1": {"range_m": [0, 0.03], "velocity_m_s": 0.1, "effort": 20}}
    assert cli("validate", _panda(tmp_path, robot=robot, safety=None)).returncode == 0


def test_a_scara_s_quill_is_given_planned_limited_and_judged_in_metres(tmp_path):
    """examples/robots/dh_scara.yaml: a DH table with a prismatic row; its postures in `joints:` (degrees and the
    quill in metres), a Cartesian target by the numeric IK, the quill's envelope in metres, m/s and N."""
    result = Runner(load_scenario(SCARA), out_dir=tmp_path).run()
    assert result.passed, result.failures
    s, m = result.summary, result.metrics
    assert s["plans"][0]["waypoints_deg"][:2] == [[30.0, 60.0, 0.02, 0.0], [-20.0, 90.0, 0.15, 45.0]]
    quill = s["per_joint"]["quill"]["range_m"]
    assert quill[0] == pytest.approx(0.02, abs=1e-4) and 0.15 <= quill[1] < 0.155  # (the spline's swing past 0.15)
    assert m["rom_m_quill"] == pytest.approx(quill[1] - quill[0], abs=1e-6) and "rom_deg_quill" not in m
    assert m["rom_deg_elbow"] == pytest.approx(30.0, abs=1.0) and m["final_position_error_m"] < 1e-3
    # the place target's 0.2 m height (base frame): 0.4 - quill - 0.05 - 0.08 (the tool), the quill at 0.07 m
    assert result.trace.q[-1, 2] == pytest.approx(0.07, abs=1e-4)
    limits = next(json.loads(line) for line in (tmp_path / "safety_log.jsonl").read_text().splitlines()
                  if '"kind": "limits"' in line)["joints"]["quill"]
    assert (limits["lower_m"], limits["upper_m"], limits["velocity_m_s"], limits["effort_n"]) == (0.0, 0.18, 0.3, 150.0)
    refused = cli("validate", SCARA, "--set", "safety.joints.quill={range_deg: [0, 10]}")
    assert refused.returncode == 2 and refused.stderr.startswith("<--set safety.joints.quill>: ")  # (where it is)
    assert "safety.joints.quill.range_deg: quill is a prismatic joint: range_deg [deg] is for a revolute joint; " \
           "write range_m instead, in m (the robot's own: [0, 0.2] m)" in refused.stderr


def test_a_prismatic_joint_s_breaches_are_said_in_metres_and_newtons_and_its_margin_is_in_metres():
    """The safety layer on a revolute joint and a slide (tests/data/slide2.urdf, 0-0.2 m, 100 N): the slide trips
    `position_margin_m` (5 mm) beyond its range — 0.5° read as metres was 8.7 mm — and its position and force
    breaches are said in m and N."""
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.safety.layer import SafetyLayer
    from rehabkit.core.scenario.safety import SafetyConfig

    info = default_registry().get("robot", "urdf")
    robot = info.factory(info.config.model_validate({"type": "urdf", "file": str(ROOT / "tests" / "data" /
                                                     "slide2.urdf"), "ee_frame": "l2"}),
                         Context(ROOT, np.random.default_rng(0), 0.001))

    def step(q_slide: float, force: float, speed: float = 0.0, **config):
        layer = SafetyLayer(robot.model, SafetyConfig(**config))
        layer.check_row(0.0, np.array([0.0, q_slide, 0.0, speed, 0.0, force]))  # (q, qd, tau)
        return layer.events

    assert step(0.204, 10.0) == [] and step(0.204, 120.0) == []  # within the margin; a force clipped
    (beyond,) = step(0.207, 10.0)  # 7 mm out: beyond the 5 mm margin
    assert (beyond.rule, beyond.joint, beyond.value, beyond.limit) == ("position", "slide", 0.207, pytest.approx(0.205))
    assert "slide beyond its position limit (0.207 m, limit 0.205 m)" in beyond.message
    assert step(0.207, 10.0, position_margin_m=0.01) == []
    (fast,) = step(0.1, 10.0, speed=0.6)
    assert "slide beyond its velocity limit (0.6 m/s, limit 0.5 m/s)" in fast.message
    (pushed,) = step(0.1, 120.0, torque_policy="stop")
    assert pushed.rule == "torque" and "slide beyond its force limit (120.0 N, limit 100.0 N)" in pushed.message
