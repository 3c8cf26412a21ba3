"""Joint matrix, RRT + GA planning and the CaPaMan obstacle scenario."""

import json
import subprocess
import sys

import numpy as np
import pytest

from rehabkit.core.scenario.models import Pose, WorldObject
from rehabkit.cspace.joint_matrix import build_joint_matrix
from rehabkit.cspace.occupancy import rasterise
from rehabkit.estimation.kalman import ConstantRateModel, KalmanBank
from rehabkit.testing import group
from tests.conftest import ROOT, SCENARIOS

CAPAMAN = SCENARIOS / "capaman_obstacle.yaml"


def test_occupancy_grid_marks_obstacles_and_measures_distance():
    cyl = WorldObject(name="c", shape="cylinder", size=[0.02, 0.05], pose=Pose(position=(0.1, 0.0, 1.0)))
    psi = rasterise([cyl], np.eye(4), np.array([0.0, -0.1, 0.9]), np.array([0.2, 0.1, 1.1]), 0.005)
    assert psi.hits(np.array([[0.1, 0.0, 1.0]]))[0] and not psi.hits(np.array([[0.1, 0.05, 1.0]]))[0]
    assert psi.clearance(np.array([[0.1, 0.06, 1.0]]))[0] == pytest.approx(0.04, abs=0.006)
    grown = rasterise([cyl], np.eye(4), np.array([0.0, -0.1, 0.9]), np.array([0.2, 0.1, 1.1]), 0.005, inflate=0.01)
    assert grown.occupied.sum() > psi.occupied.sum() and grown.hits(np.array([[0.1, 0.027, 1.0]]))[0]


def test_joint_matrix_agrees_with_mujoco_contacts(rng):
    """Configurations Θ marks free have no contact with the obstacle in MuJoCo, and colliding ones do."""
    import mujoco
    from rehabkit_plugins.robots.capaman import CapamanConfig, CapamanRobot

    from rehabkit.core.scenario.models import World
    from rehabkit.sim.scene import build_scene

    robot = CapamanRobot(CapamanConfig(base={"position": [0, 0, 0.75]}))
    world = World(floor=False, objects=[WorldObject(name="obstacle", shape="cylinder", size=[0.015, 0.08],
                                                    pose=Pose(position=(0.0, 0.0, 1.135)))])
    lim = robot.model.limits
    pts = robot.cluster_points(np.stack(np.meshgrid(*[np.linspace(lo, hi, 5) for lo, hi in zip(lim.lower, lim.upper)],
                                                    indexing="ij"), -1).reshape(-1, 3)).reshape(-1, 3)
    psi = rasterise(world.objects, robot.model.base_pose, pts.min(0) - 0.03, pts.max(0) + 0.03, 0.005,
                    inflate=robot.link_radius)
    theta = build_joint_matrix(robot.cluster_points, psi, lim.lower, lim.upper, np.radians(3))
    assert 0.5 < theta.free.mean() < 0.95
    m = build_scene(robot.model, world, 0.001).compile()
    d = mujoco.MjData(m)
    obstacle = m.geom("obstacle").id
    agree = 0
    samples = rng.uniform(lim.lower, lim.upper, (60, 3))
    for q in samples:
        values = {f"alpha_{k + 1}": np.array([q[k]]) for k in range(3)} | robot.passive_state(q)
        for name, v in values.items():
            adr = m.jnt_qposadr[m.joint(name).id]
            d.qpos[adr : adr + len(np.atleast_1d(v))] = v
        mujoco.mj_forward(m, d)
        touching = any(obstacle in (c.geom1, c.geom2) for c in d.contact[: d.ncon])
        free = bool(theta.is_free(q))
        if free:
            assert not touching or theta.clearance(q) <= theta.step  # grid cells next to a collision
        agree += free != touching
    assert agree >= 54  # nearest-node look-ups can differ within one grid step of the boundary


def test_adaptive_filter_follows_fast_changes_and_smooths_slow_ones():
    dt = 0.001
    t = np.arange(0, 4, dt)
    slow = np.sin(0.5 * t)
    fast = np.where(t < 2, 0.0, 3 * np.sin(12 * (t - 2)))  # a quick swing starting at 2 s
    rng = np.random.default_rng(0)
    truth = np.stack([slow, fast, slow], 1)[:, None, :]
    noisy = truth + rng.normal(0, 0.5, truth.shape)
    out = {}
    for adaptive in (False, True):
        bank = KalmanBank(ConstantRateModel(dt), 1, adaptive=adaptive)
        est = np.array([bank.step(z) for z in noisy])
        out[adaptive] = (np.sqrt(np.mean((est[2200:, 0, 1] - truth[2200:, 0, 1]) ** 2)),
                         np.sqrt(np.mean((est[500:2000] - truth[500:2000]) ** 2)))
    assert out[True][0] < out[False][0] / 2  # follows the quick swing
    assert out[True][1] < 0.5 / 3  # still smooths where nothing happens


@pytest.fixture(scope="module")
def capaman_run(scenario_run):
    return scenario_run(CAPAMAN)  # the scenario's own run (its scenario test reads the same one)


@pytest.mark.xdist_group(group(CAPAMAN))
def test_obstacle_run_is_collision_free_both_ways_and_the_ga_improves(capaman_run):
    summary = capaman_run.summary
    assert capaman_run.passed, capaman_run.failures
    m, plan = summary["metrics"], summary["plans"][0]
    assert m["contact_steps"] == 0 and m["executed_colliding_configurations"] == 0
    assert plan["direct_motion_collides"] == 1  # the obstacle stands between the task points
    assert plan["fitness_best_ga"] < plan["fitness_best_rrt"]
    assert plan["path_length_ga_rad"] <= plan["path_length_rrt_rad"] + 1e-9
    assert plan["fitness_per_generation"] == sorted(plan["fitness_per_generation"], reverse=True)  # elitism
    assert len(plan["waypoints_deg"]) == 21 and plan["waypoints_deg"][0] == plan["waypoints_deg"][-1]
    assert m["accel_filter_gain"] >= 3 and m["omega_filter_gain"] >= 3


@pytest.mark.xdist_group(group(CAPAMAN))
def test_validation_report_compares_with_truth_and_plan(capaman_run):
    summary = capaman_run.summary
    m, report = summary["metrics"], summary["reports"]["imu"]
    assert "vs planned motion" in report and "vs MuJoCo truth" in report  # (the CLI prints it: see below)
    assert report.count("\n") >= 6
    # the planned motion is what MuJoCo executed, closely: the comparison measures the sensors, not the tracking
    assert m["accel_rms_true_vs_planned_m_s2"] < 0.02 and m["omega_rms_true_vs_planned_rad_s"] < 0.005
    assert m["accel_rms_raw_vs_planned_m_s2"] > 3 * m["accel_rms_filtered_vs_planned_m_s2"]


@pytest.mark.xdist_group(group(CAPAMAN))
def test_joint_space_is_in_the_log(capaman_run):
    import shutil

    text = subprocess.run([shutil.which("rerun"), "rrd", "print", str(capaman_run.out_dir / "run.rrd")],
                          capture_output=True, text=True, timeout=120).stdout
    for entity in ("/joint_space/colliding_region", "/joint_space/plan", "/joint_space/executed",
                   "/sensors/imu/acc_filtered", "/sensors/imu/acc_true", "/world/scene/obstacle"):
        assert entity in text, entity


@pytest.mark.xdist_group(group(CAPAMAN))
def test_planning_is_deterministic_across_processes(capaman_run, tmp_path):
    """A fresh process plans what this one did (after whatever it planned before), and the CLI prints the
    validation report."""
    r = subprocess.run([sys.executable, "-m", "rehabkit.cli", "run", str(CAPAMAN), "--out", str(tmp_path),
                        "--set", "duration=0.5", "--set", "expect=null"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    again = json.loads((tmp_path / "summary.json").read_text())
    assert again["plans"][0]["waypoints_deg"] == capaman_run.summary["plans"][0]["waypoints_deg"]
    assert "imu:\n" in r.stdout and "vs planned motion" in r.stdout and "vs MuJoCo truth" in r.stdout


@pytest.mark.parametrize("interval", [0.09, 0.9])
def test_the_papers_other_speeds(run_scenario, interval):
    r = run_scenario(CAPAMAN, write=False, planner__point_interval_s=interval)
    assert r.passed, r.failures  # includes the smoothed validation gains >= 3 while moving and vs the plan
    assert r.metrics["omega_filter_gain_moving"] >= 3
    # online, while moving, acceleration filtering gains less at the fastest speed (reported in the issue note)
    assert r.metrics["accel_filter_gain_moving"] >= (1.5 if interval < 0.1 else 3)
