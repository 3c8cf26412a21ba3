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
from rehabkit.core.setup.limits import WrongUnitKey
from tests.conftest import ROOT
from tests.located import located, refusal, said, set_located
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
    record = next(json.loads(line) for line in (out / "safety_log.jsonl").read_text().splitlines()
                  if '"kind": "limits"' in line)
    # the trip margins and the stops' deceleration bounds of both kinds of joint (a Panda has both), as in force
    assert (record["position_margin_deg"], record["position_margin_m"]) == (0.5, 0.005)
    assert record["stop_decel_deg_s2"] is None and record["stop_decel_m_s2"] is None
    limits = record["joints"]
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
    keys = ("panda_finger_joint1.range_deg", "panda_finger_joint1.torque_nm", "panda_joint2.velocity_m_s")
    found = located(refused.stderr)
    assert [at for *_, at in found] == [f"safety.joints.{key}" for key in keys]
    for (_, row, col, _), key in zip(found, keys, strict=True):  # each at its key in the file
        name = key.split(".")[1]
        assert text[row - 1][col - 1:col - 1 + len(name)] == name, (row, col, name)
    # each with the key to write and the robot's own limit in the joint's unit (worded: tests/test_message_wording.py)
    assert said(refused.stderr) == [k.describe() for k in (
        WrongUnitKey("panda_finger_joint1", "range_deg", "range_m", False, "[0, 0.04] m"),
        WrongUnitKey("panda_finger_joint1", "torque_nm", "force_n", False, "100 N"),
        WrongUnitKey("panda_joint2", "velocity_m_s", "velocity_deg_s", True, "124.6 deg/s"))]
    robot = {**PANDA, "limits": {"panda_finger_joint1": {"range_deg": [0, 0.03]}}}
    (d,) = refusal(_panda(tmp_path, robot=robot)).diagnostics
    assert (d.path, d.fix) == ("robot.limits.panda_finger_joint1.range_deg", "write range_m instead")
    robot["limits"] = {"panda_finger_joint1": {"range_m": [0, 0.03], "velocity_m_s": 0.1, "effort": 20}}
    assert cli("validate", _panda(tmp_path, robot=robot, safety=None)).returncode == 0


def test_a_scara_s_quill_is_given_planned_limited_and_judged_in_metres(tmp_path):
    """examples/robots/dh_scara.yaml: a DH table with a prismatic row; its postures in `joints:` (degrees and the
    quill in metres), a Cartesian target by the numeric IK, the quill's envelope in metres, m/s and N."""
    result = Runner(load_scenario(SCARA), out_dir=tmp_path).run()
    assert result.passed, result.failures
    s, m = result.summary, result.metrics
    assert s["plans"][0]["waypoints"][:2] == [[30.0, 60.0, 0.02, 0.0], [-20.0, 90.0, 0.15, 45.0]]
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
    assert refused.returncode == 2 and set_located(refused.stderr) == [("safety.joints.quill",
                                                                        "safety.joints.quill.range_deg")]
    assert said(refused.stderr) == [WrongUnitKey("quill", "range_deg", "range_m", False, "[0, 0.2] m").describe()]


@pytest.fixture(scope="module")
def slide2():
    """tests/data/slide2.urdf: a revolute joint j1 (±2 rad) and a slide (0-0.2 m, 0.5 m/s, 100 N)."""
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.plugins.registry import default_registry

    info = default_registry().get("robot", "urdf")
    return info.factory(info.config.model_validate({"type": "urdf", "file": str(ROOT / "tests" / "data" /
                                                    "slide2.urdf"), "ee_frame": "l2"}),
                        Context(ROOT, np.random.default_rng(0), 0.001))


def test_a_prismatic_joint_s_breaches_are_said_in_metres_and_newtons_and_its_margin_is_in_metres(slide2):
    """The safety layer on a revolute joint and a slide (tests/data/slide2.urdf, 0-0.2 m, 100 N): the slide trips
    `position_margin_m` (5 mm) beyond its range — 0.5° read as metres was 8.7 mm — and its position and force
    breaches are said in m and N."""
    from rehabkit.core.safety.layer import SafetyLayer
    from rehabkit.core.scenario.safety import SafetyConfig

    robot = slide2

    def step(q_slide: float, force: float, speed: float = 0.0, **config):
        layer = SafetyLayer(robot.model, SafetyConfig(**config))
        layer.check_row(0.0, np.array([0.0, q_slide, 0.0, speed, 0.0, force]))  # (q, qd, tau)
        return layer.events

    assert step(0.204, 10.0) == [] and step(0.204, 120.0) == []  # within the margin; a force clipped
    (beyond,) = step(0.207, 10.0)  # 7 mm out: beyond the 5 mm margin
    assert (beyond.rule, beyond.joint, beyond.value, beyond.limit) == ("position", "slide", 0.207, pytest.approx(0.205))
    assert (beyond.breach.quantity, beyond.breach.revolute) == ("position", False)  # said in metres: not revolute
    assert step(0.207, 10.0, position_margin_m=0.01) == []
    (fast,) = step(0.1, 10.0, speed=0.6)
    assert (fast.rule, fast.joint, fast.value, fast.limit) == ("velocity", "slide", 0.6, pytest.approx(0.5))
    assert (fast.breach.quantity, fast.breach.revolute) == ("velocity", False)  # in m/s
    (pushed,) = step(0.1, 120.0, torque_policy="stop")
    assert (pushed.rule, pushed.joint, pushed.value, pushed.limit) == ("torque", "slide", 120.0, 100.0)
    assert (pushed.breach.quantity, pushed.breach.revolute) == ("torque", False)  # a force, in N


def test_a_stop_s_figures_give_each_kind_of_joint_in_its_own_unit():
    """stop_figures on a revolute joint and a slide: the revolute joint's travel and peak speed in deg and deg/s, the
    slide's in m and m/s (they were one figure, the slide's read as mm), the hand's path in m; a robot without a
    slide has no metres figures; the catalogue gives each its unit."""
    from rehabkit.core.kinds.metric import CORE_METRICS
    from rehabkit.core.safety.stopping import stop_figures

    t = np.arange(0.0, 0.5, 0.001)
    decay = np.exp(-np.maximum(t - 0.1, 0.0) / 0.02)  # each joint slows from its speed at the trip (t = 0.1 s)
    qd = np.stack([np.radians(30.0) * decay, 0.05 * decay], axis=1)  # 30 °/s and 50 mm/s at the trip
    q = np.cumsum(qd, axis=0) * 0.001
    hand = np.zeros((len(t), 3))
    hand[:, 0] = q[:, 1]
    figures = stop_figures(t, q, qd, hand, 0.1, np.array([True, False]))
    # at rest once the revolute joint is below 1 °/s (68 ms) and the slide below 1 mm/s: 50·e^(-t/0.02) < 1 at 78 ms
    assert figures["stop_time_s"] == pytest.approx(0.02 * np.log(50.0), abs=2e-3)
    # meanwhile each joint travels v₀·τ·(1 - 1/50): 0.588° and 0.98 mm (less half a step of the sum: 2.5 %)
    assert figures["stop_distance_deg"] == pytest.approx(30.0 * 0.02 * 0.98, rel=0.03)
    assert figures["stop_joint_travel_m"] == pytest.approx(0.05 * 0.02 * 0.98, rel=0.03)
    assert figures["stop_peak_speed_deg_s"] == pytest.approx(30.0) and figures["stop_joint_peak_speed_m_s"] == 0.05
    assert figures["stop_distance_m"] == pytest.approx(figures["stop_joint_travel_m"], rel=1e-12)  # (the hand's)
    both = stop_figures(t, q[:, [0, 0]], qd[:, [0, 0]], None, 0.1, np.array([True, True]))
    assert {"stop_joint_travel_m", "stop_joint_peak_speed_m_s"}.isdisjoint(both)
    units = {m.name: m.unit for m in CORE_METRICS}
    assert (units["stop_joint_travel_m"], units["stop_joint_peak_speed_m_s"]) == ("m", "m/s")


def test_a_force_reaction_s_speeds_and_walls_are_metres_on_a_slide_and_a_key_of_a_kind_the_robot_lacks_is_refused(
        tmp_path):
    """safety.reactions on a slide: its own keys in m and m/s (the degrees ones were read as mm); on HIT (all
    revolute) a metres key is refused at its line, with the key to write, and so is stop_decel_m_s2."""
    from rehabkit.core.safety.compliance import Compliance
    from rehabkit.core.scenario.safety import ForceReaction

    lo, hi = np.array([-2.0, 0.0]), np.array([2.0, 0.2])
    reaction = ForceReaction(type="retreat", max_speed_m_s=0.1, wall_m=0.02, retreat_speed_m_s=0.05)
    c = Compliance(reaction, 30.0, 0.0, np.array([0.0, 0.1]), lo, hi, np.array([True, False]), np.array([30.0, 100.0]),
                   np.eye(2), None, None, 60.0, 6.0, lambda q, f: np.array([0.0, f[0]]))
    assert np.allclose(c.vmax, [np.radians(60.0), 0.1]) and np.allclose(c.vretreat, [np.radians(20.0), 0.05])
    assert np.allclose(c.wall_lo, [-2.0 + np.radians(10.0), 0.02]) and np.allclose(c.wall_hi, [2.0 - np.radians(10.0),
                                                                                              0.18])
    c.observe(0.01, np.array([0.0, 0.1]), np.array([40.0, 0.0, 0.0]))  # pushed along the slide: it retreats at 5 cm/s
    assert c.qd_ref == pytest.approx([0.0, 0.05])
    with pytest.raises(ValueError, match=r"retreat_speed_m_s \(0.1\) must be below max_speed_m_s \(0.06\)"):
        ForceReaction(type="retreat", retreat_speed_m_s=0.1)
    path = tmp_path / "hit.yaml"
    path.write_text(f"extends: {ROOT / 'scenarios' / 'hit_roundtrip.yaml'}\nsafety:\n  interaction_force_n: 30\n"
                    "  stop_decel_m_s2: 2\n  reactions:\n"
                    "    interaction-force: {type: yield, wall_deg: 5, wall_m: 0.02}\n")
    refused = cli("validate", path)
    assert refused.returncode == 2
    lines = path.read_text().splitlines()
    assert (lines[3].index("stop_decel_m_s2"), lines[5].index("wall_m")) == (2, 50)  # (the columns below, 0-based)
    assert refused.stderr.splitlines() == [
        f"{path}:4:3: safety.stop_decel_m_s2: robot 'hit' has no prismatic joint: stop_decel_m_s2 [m/s²] is for "
        "prismatic joints; write stop_decel_deg_s2 instead, in deg/s², for its revolute joints",
        f"{path}:6:51: safety.reactions.interaction-force.wall_m: robot 'hit' has no prismatic joint: wall_m [m] is "
        "for prismatic joints; write wall_deg instead, in deg, for its revolute joints"]


def test_a_controlled_stop_s_deceleration_is_each_kind_s_own_and_the_hold_gains_say_n_per_m(slide2):
    """stop_decel_deg_s2 bounds the revolute joint (in rad/s²), stop_decel_m_s2 the slide (m/s²; 360 was read as
    0.36 m/s²); one of them alone leaves the other joint its drive's own; hold_kp/kd say N/m on a slide."""
    from rehabkit.core.safety.stopping import ControlledStop, stop_decel
    from rehabkit.core.scenario.safety import SafetyConfig

    revolute = slide2.model.revolute
    assert np.allclose(stop_decel(SafetyConfig(stop_decel_deg_s2=360, stop_decel_m_s2=2.0), revolute),
                       [2 * np.pi, 2.0])
    only = stop_decel(SafetyConfig(stop_decel_deg_s2=360), revolute)
    assert only[0] == pytest.approx(2 * np.pi) and np.isnan(only[1])
    q, qd = np.array([0.0, 0.1]), np.array([np.pi, 0.4])
    stop = ControlledStop.start(1, 0.0, q, qd, only, slide2.model.limits.effort, slide2.model, 0.001)
    own = ControlledStop.start(1, 0.0, q, qd, None, slide2.model.limits.effort, slide2.model, 0.001)
    assert stop.duration == pytest.approx(max(0.5, own.duration))  # π rad/s at 2π rad/s², or the slide at its own
    fields = SafetyConfig.model_fields
    assert "N/m for a prismatic joint" in fields["hold_kp"].description
    assert "N·s/m for a prismatic joint" in fields["hold_kd"].description


def test_a_patient_s_comfort_speed_is_degrees_on_revolute_joints_and_metres_on_a_slide(slide2):
    """comfort.max_speed_deg_s narrows the revolute joints only (a slide got it as rad/s read as m/s), and
    comfort.max_speed_m_s the slides; a range of motion given for a slide is refused at its line."""
    from types import SimpleNamespace

    from rehabkit.core.scenario.errors import Mark, ScenarioError
    from rehabkit.rehab.admission import profile_narrowings
    from rehabkit.rehab.patient import patient_narrowings
    from rehabkit.rehab.profile import PatientBase

    model = slide2.model
    patient = PatientBase(id="P9", side="right", comfort={"max_speed_deg_s": 30})
    assert [(n.joint, n.key, n.value) for n in patient_narrowings(model, patient)] == [
        ("j1", "velocity", pytest.approx(np.radians(30.0)))]
    patient = PatientBase(id="P9", side="right", comfort={"max_speed_deg_s": 30, "max_speed_m_s": 0.1})
    assert [(n.joint, n.value) for n in patient_narrowings(model, patient)] == [
        ("j1", pytest.approx(np.radians(30.0))), ("slide", 0.1)]
    patient = PatientBase(id="P9", side="right", joints={"slide": {"passive_deg": [0, 10]}})
    source = SimpleNamespace(key_marks={("patient", "joints", "slide"): Mark("p.yaml", 4, 3)},
                             value_marks={(): Mark("p.yaml", 0, 0)})
    with pytest.raises(ScenarioError) as refused:
        profile_narrowings(model, patient, source)
    (d,) = refused.value.diagnostics  # at the slide's entry, with where to limit it instead: the robot's own range
    assert (d.mark, d.path) == (Mark("p.yaml", 4, 3), "patient.joints.slide")
    assert d.fix == ("limit a prismatic joint in the safety envelope instead, in metres (safety.joints.slide: "
                     "{range_m: [0, 0.2], velocity_m_s: ...}: the robot's own range)")


def test_an_assessment_cues_in_si_and_measures_the_revolute_joints_only(slide2):
    """The assessment's targets are `joints_rad` (its `joints_deg` refused a robot with a slide): on the SCARA the
    cue postures resolve to the very joint values; it measures revolute joints, and --joints naming a slide is
    refused with the joints it can measure."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.setup.assembly import assemble
    from rehabkit.rehab.assess import assessed_joints, posture_target
    from rehabkit.rehab.profile import PatientBase

    q = np.array([0.5, 1.0, 0.05, 0.25])
    cues = [posture_target("start", q), posture_target("cue0", q + [0.1, -0.2, 0.1, 0.0])]
    assert cues[0] == {"name": "start", "joints_rad": [0.5, 1.0, 0.05, 0.25]}
    a = assemble(load_scenario(SCARA, {"task": {"targets": cues}}), default_registry(), default_extensions(),
                 upto="targets")
    assert np.allclose(a.targets["start"].q, q) and np.allclose(a.targets["cue0"].q, [0.6, 0.8, 0.15, 0.25])
    profile = PatientBase(id="P9", side="right")
    assert assessed_joints(slide2.model, profile) == ["j1"]
    with pytest.raises(ValueError, match=r"^--joints: slide is a prismatic joint: an assessment measures a person's "
                                         r"range of motion on revolute joints \(in degrees\); leave it out \(its "
                                         r"revolute joints: j1\)$"):
        assessed_joints(slide2.model, profile, ["j1", "slide"])


def test_an_encoder_reads_a_slide_in_metres_and_the_recording_shows_it_so(slide2, tmp_path):
    """joint-encoder on a revolute joint and a slide: `position_rad` (4096 counts/rev) and `position_m` (10 µm
    counts: the slide was quantised in 1.5 mm steps as an angle), each joint named; the recording shows the angle in
    degrees and the slide in metres, and the joint space's axes in each joint's unit."""
    from rehabkit.core.kinds.context import Context
    from rehabkit.core.log.rerun_log import RerunLog
    from rehabkit.core.plugins.registry import default_registry

    info = default_registry().get("sensor", "joint-encoder")
    context = Context(ROOT, np.random.default_rng(0), 0.001, robot=slide2)
    encoder = info.factory(info.config.model_validate({"type": "joint-encoder"}), context)
    reading = encoder.read(0.0, np.array([0.5, 0.123456]), np.zeros(2), None)
    step = 2 * np.pi / 4096
    assert reading["position_rad"] == pytest.approx([round(0.5 / step) * step]) and reading["position_m"] == \
        pytest.approx([0.12346], abs=1e-12)
    assert encoder.channels("position_rad", 1) == ["j1"] and encoder.channels("position_m", 1) == ["slide"]
    log = RerunLog(tmp_path / "run.rrd", "test", ["j1", "slide", "j3"], revolute=[True, False, True])
    log.sensor(0.0, "enc", reading, encoder.channels)
    log.contents.joint_space = True
    log.line("joint_space/executed", log.in_own_units(np.array([[np.pi / 2, 0.1, -np.pi]])), (0, 0, 0), 0.3)
    log.close()
    data = recording(tmp_path / "run.rrd")
    assert data["sensors/enc/position_m"]["SeriesLines:names"] == [["position [m]"]]
    assert np.ravel(data["sensors/enc/position_m"]["Scalars:scalars"]) == pytest.approx([0.12346])
    assert np.ravel(data["sensors/enc/position_deg"]["Scalars:scalars"]) == pytest.approx(
        [np.degrees(round(0.5 / step) * step)])
    assert np.ravel(data["joint_space/executed"]["LineStrips3D:strips"]) == pytest.approx([90.0, 0.1, -180.0])
    titles = {v[1]: v[2] for v in _flat(read_layout(tmp_path / "run.rrd")[0])}
    assert titles["joint space [deg, m, deg]"] == "joint_space"


def test_the_bridge_s_and_the_drives_backstop_is_a_metres_margin_on_a_slide(slide2):
    """The bridge's own limit check: 2° beyond a revolute joint's range, 10 mm beyond a slide's (2° read as metres
    was 35 mm; the host's margin is 5 mm); the CANopen drives get the same backstop and each kind's deceleration."""
    from rehabkit.canopen.drives.limits import drive_limits
    from rehabkit.core.scenario.safety import SafetyConfig
    from rehabkit.hardware.bridge_limits import BridgeLimits

    lim = slide2.model.limits
    backstop = BridgeLimits(lim.lower, lim.upper, lim.velocity, revolute=slide2.model.revolute)
    assert backstop.breach(np.array([2.0 + np.radians(1.9), 0.209]), np.zeros(2)) is None
    assert backstop.breach(np.array([0.0, 0.211]), np.zeros(2)) == \
        "joint 1 beyond its upper limit: 0.2110 (limit 0.2000)"
    assert backstop.breach(np.array([2.0 + np.radians(2.1), 0.1]), np.zeros(2)).startswith("joint 0 beyond its upper")
    drives = drive_limits(slide2.model, SafetyConfig(stop_decel_deg_s2=360, stop_decel_m_s2=2.0), np.zeros(2))
    assert np.allclose(drives.upper, [2.0 + np.radians(2.0), 0.21]) and np.allclose(drives.decel, [2 * np.pi, 2.0])


def test_validate_lists_the_joints_in_the_order_a_posture_gives_them(capsys):
    """What a user writing `joints: [...]` needs: each joint, its kind and the limits in force, in its own unit."""
    from rehabkit.cli.main import main

    assert main(["validate", str(ROOT / "examples" / "robots" / "dh_scara.yaml"), "--joints"]) == 0
    rows = [x.strip() for x in capsys.readouterr().out.splitlines() if x.strip().startswith("JOINT")]
    assert [r.split(". ")[1].split(":")[0] for r in rows] == ["shoulder", "elbow", "quill", "roll"]
    quill = next(r for r in rows if "prismatic" in r)
    assert " m, " in quill and " m/s, " in quill and quill.endswith(" N")
