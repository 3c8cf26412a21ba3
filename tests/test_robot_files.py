"""Robots without code: MJCF files, URDF files and DH tables written in the scenario."""

import textwrap

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from rehabkit.api import run_scenario
from rehabkit.core.run.runner import SetupError
from tests.conftest import DATA
from tests.located import located, refusal

COMMON = """\
    planner: {type: multi-cubic, segment_durations: [1.5, 1.5]}
    controller: {type: joint-pd, kp: 150, kd: 8, feedforward: inverse-dynamics}
    duration: 3.5
    expect:
      final_joint_error_deg: {lt: 0.5}
      tracking_max_deg: {lt: 2.0}
      safety_events: {eq: 0}
"""


def scenario(tmp_path, robot_yaml: str, targets: str) -> str:
    p = tmp_path / "s.yaml"
    p.write_text(textwrap.dedent(robot_yaml) + textwrap.dedent(COMMON) + textwrap.dedent(targets))
    return p


def _same_robot_in_both_engines(model, rng):
    mj = mujoco.MjModel.from_xml_string(model.mjcf)
    d = mujoco.MjData(mj)
    pd = model.pin_model.createData()
    for _ in range(10):
        q = rng.uniform(model.limits.lower, model.limits.upper)
        d.qpos[:] = q
        mujoco.mj_forward(mj, d)
        M = np.zeros((model.dof, model.dof))
        mujoco.mj_fullM(mj, d, M)
        np.testing.assert_allclose(pin.crba(model.pin_model, pd, q), M, atol=1e-10)
        np.testing.assert_allclose(model.ee_pose(q)[:3, 3], d.site_xpos[mj.site(model.ee_site).id], atol=1e-10)


def test_mjcf_robot_runs_and_reads_limits_from_the_file(tmp_path, rng):
    p = scenario(tmp_path, f"""\
        robot:
          type: mjcf
          file: {DATA / 'arm3.xml'}
          ee_frame: tool
          default_velocity_deg_s: 120
          base: {{position: [0, 0, 0.5]}}
        """, """\
        task:
          targets:
            - {name: home, joints_deg: [0, -30, 60]}
            - {name: reach, joints_deg: [45, 10, 40]}
            - {name: back, same_as: home}
        """)
    r = run_scenario(p)
    assert r.passed, r.failures
    from rehabkit_plugins.robots.mjcf import MjcfRobot

    from rehabkit.core.kinds.interfaces import Context
    from rehabkit.models.files.mjcf_import import ModelFileConfig

    robot = MjcfRobot(ModelFileConfig(file=str(DATA / "arm3.xml"), ee_frame="tool", default_velocity_deg_s=120),
                      Context(tmp_path, rng, 0.001))
    np.testing.assert_allclose(robot.model.limits.effort, [20, 30, 15])  # motor ctrlrange x gear
    np.testing.assert_allclose(np.degrees(robot.model.limits.upper), [170, 100, 140])
    _same_robot_in_both_engines(robot.model, rng)


def test_urdf_robot_takes_speed_and_effort_from_the_urdf(tmp_path, rng, monkeypatch):
    p = scenario(tmp_path, f"""\
        robot: {{type: urdf, file: {DATA / 'arm2.urdf'}, ee_frame: l2, base: {{position: [0, 0, 0.8]}}}}
        """, """\
        task:
          targets:
            - {name: a, joints_deg: [0, 0]}
            - {name: b, joints_deg: [-40, 60]}
            - {name: c, same_as: a}
        """)
    import tempfile

    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))  # (this process's temporary folder)
    r = run_scenario(p)
    assert r.passed, r.failures
    assert r.summary["plugins"]["robot"]["type"] == "urdf"
    # (Pinocchio reads the robot's MJCF from a file: removed once read, 45 had gathered in /tmp before)
    assert not list((tmp_path / "tmp").iterdir())


def test_missing_limits_are_named(tmp_path):
    p = scenario(tmp_path, f"""\
        robot: {{type: mjcf, file: {DATA / 'arm3.xml'}, ee_frame: tool}}
        """, "task:\n  targets: [{name: a, joints_deg: [0, 0, 0]}]\n")
    with pytest.raises(SetupError) as refused:
        run_scenario(p)
    (d,) = refused.value.diagnostics  # (said at the robot's type: the file lacks it)
    assert (d.path, d.fix) == ("robot.type", "add limits.yaw.velocity_deg_s or default_velocity_deg_s")


def test_dh_robot_written_in_yaml(tmp_path, rng):
    # a standard-DH 3R arm: yaw, then two pitch joints of 0.3 m and 0.25 m
    p = scenario(tmp_path, """\
        robot:
          type: dh
          name: arm-3r
          convention: standard
          base: {position: [0, 0, 0.6]}
          table:
            - {a: 0.0, alpha_deg: 90, d: 0.2}
            - {a: 0.3, alpha_deg: 0, d: 0.0}
            - {a: 0.25, alpha_deg: 0, d: 0.0}
          joints:
            - {name: yaw, range_deg: [-170, 170], velocity_deg_s: 120, effort: 30, mass: 1.0, armature: 0.02}
            - {name: shoulder, range_deg: [-120, 120], velocity_deg_s: 120, effort: 30, mass: 1.2, armature: 0.02}
            - {name: elbow, range_deg: [-150, 150], velocity_deg_s: 120, effort: 15, mass: 0.8, armature: 0.01}
        """, """\
        task:
          targets:
            - {name: a, joints_deg: [0, 30, -60]}
            - {name: b, joints_deg: [60, 60, -30]}
            - {name: c, same_as: a}
        """)
    r = run_scenario(p)
    assert r.passed, r.failures
    # the generated model's tip is where the DH product says it is
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.models.chain import sdh_transform
    from rehabkit.models.dh import DHRobotSpec

    spec = load_scenario(p).model.robot
    from rehabkit_plugins.robots.dh import DHRobot

    robot = DHRobot(spec)
    q = np.radians([20, 40, -70])
    t = np.eye(4)
    for row, qi in zip(DHRobotSpec.model_validate(spec.model_dump(exclude={"type"})).table, q):
        t = t @ sdh_transform(row.row(), qi)
    np.testing.assert_allclose(robot.model.ee_pose(q), t, atol=1e-12)
    _same_robot_in_both_engines(robot.model, rng)


def test_urdf_limits_written_in_degrees_are_refused_with_their_radians(tmp_path):
    """URDF limits are radians; lower="-110" upper="110" (the shoulder's ±1.9 rad written in degrees) would give a
    joint 17.5 turns each way. validate refuses it at robot.file, with the values in radians."""
    from tests.conftest import ROOT
    from tests.test_cli import cli

    urdf = (ROOT / "examples" / "robots" / "arm4.urdf").read_text()
    assert urdf.count('lower="-1.9" upper="1.9"') == 1
    (tmp_path / "arm4.urdf").write_text(urdf.replace('lower="-1.9" upper="1.9"', 'lower="-110" upper="110"'))
    scenario = (ROOT / "examples" / "robots" / "urdf_arm4.yaml").read_text()
    (tmp_path / "s.yaml").write_text(scenario)
    out = cli("validate", "s.yaml", cwd=tmp_path)
    assert out.returncode == 2
    (line,) = [x for x in out.stderr.splitlines() if "URDF limits are radians" in x]
    assert [x[3] for x in located(out.stderr)] == ["robot.file"]
    # the limits as the plugin read them, in radians (17.5 turns each way): as fields of its refusal
    assert refusal(tmp_path / "s.yaml").__cause__.data == {"joint": "shoulder", "lower": -110.0, "upper": 110.0}
    assert line.endswith('write lower="-1.9199" upper="1.9199"')


def test_a_prismatic_joint_is_read_written_and_judged_in_metres(tmp_path):
    """A revolute joint and a slide (0-0.2 m): a posture gives each joint in its own unit (`joints`: degrees, metres),
    `joints_deg` refuses the slide with the fix (a finger's 0.02 m was 0.35 mm), and the plans, ROM, per-joint figures,
    final error and the safety log's limits are in metres for it."""
    import json

    from tests.test_cli import cli

    p = tmp_path / "s.yaml"
    p.write_text(f"name: slide2\nrobot: {{type: urdf, file: {DATA / 'slide2.urdf'}, ee_frame: l2, "
                 "base: {position: [0, 0, 0.5]}}\nplanner: {type: multi-cubic, segment_durations: [2.0]}\n"
                 "controller: {type: joint-pd, gains: auto, feedforward: inverse-dynamics}\ntask:\n  targets:\n"
                 "    - {name: A, joints: [0, 0.02]}\n    - {name: B, joints: [30, 0.15]}\nduration: 2.5\n"
                 "expect: {final_joint_error_m: {lt: 0.001}}\n")
    r = cli("run", str(p), "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["plans"][0]["waypoints"] == [[0.0, 0.02], [30.0, 0.15]]
    assert s["metrics"]["rom_deg_j1"] == pytest.approx(30.0, abs=0.01)
    assert s["metrics"]["rom_m_slide"] == pytest.approx(0.13, abs=1e-4) and "rom_deg_slide" not in s["metrics"]
    assert s["per_joint"]["slide"]["range_m"] == pytest.approx([0.02, 0.15], abs=1e-4)
    limits = next(json.loads(x) for x in (tmp_path / "out" / "safety_log.jsonl").read_text().splitlines()
                  if '"kind": "limits"' in x)["joints"]["slide"]
    assert (limits["lower_m"], limits["upper_m"], limits["velocity_m_s"], limits["effort_n"]) == (0.0, 0.2, 0.5, 100.0)
    p.write_text(p.read_text().replace("joints: [30, 0.15]", "joints_deg: [30, 0.15]"))
    refused = cli("validate", str(p))
    assert (refused.returncode, [x[3] for x in located(refused.stderr)]) == (2, ["task.targets.1.joints_deg"])
    why = refusal(p).__cause__  # (B's slide, a prismatic joint, given in degrees: to be written as `joints: [...]`)
    assert (why.target, why.code) == ("B", "prismatic-in-degrees")


def test_a_misspelt_end_effector_is_said_at_its_setting_with_the_names_nearest(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(f"name: s\nrobot: {{type: urdf, file: {DATA / 'slide2.urdf'}, ee_frame: l2_e}}\n"
                 "planner: {type: multi-cubic, segment_durations: [1]}\ncontroller: {type: joint-pd}\n"
                 "task: {targets: [{name: A, joints: [0, 0.1]}]}\nduration: 1\n")
    (d,) = refusal(p).diagnostics
    assert (d.mark.file, d.mark.line, d.path) == (str(p), 2, "robot.ee_frame")
    assert d.fix == "did you mean 'l2'? (its sites and bodies: base, l1, l2, rehabkit_base)"


def test_pinocchios_file_of_a_robot_is_one_in_the_cache_per_variant(tmp_path, monkeypatch):
    """Pinocchio reads MJCF from files only: the robot's is kept in the cache by its content, written whole — a
    temporary file removed after reading was left behind by a process killed while it read."""
    import yaml

    from plugins.robots.dh import DHRobot
    from rehabkit.models.dh import DHRobotSpec

    monkeypatch.setenv("REHABKIT_CACHE", str(tmp_path))
    spec = yaml.safe_load((DATA / "arm3_dh.yaml").read_text())["robot"]
    spec.pop("type")
    for _ in range(2):  # (the same robot twice: one file)
        assert DHRobot(DHRobotSpec.model_validate(spec)).model.pin_model.nq == 3
    spec["joints"][0]["mass"] = 2.0  # (another variant: another file)
    assert DHRobot(DHRobotSpec.model_validate(spec)).model.pin_model.nq == 3
    files = sorted(p.name for p in (tmp_path / "descriptions" / "mjcf").iterdir())
    assert len(files) == 2 and all(f.startswith("arm3-") and f.endswith(".xml") for f in files)
