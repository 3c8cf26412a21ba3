"""ARM record and replay: the box-avoid planner plugin, the keypad HMI and the scenario."""

import json
import shutil
import subprocess

import numpy as np
import pytest
from rehabkit_plugins.planners.box_avoid import BoxAvoidConfig, BoxAvoidPlanner
from rehabkit_plugins.robots.arm import ArmConfig, ArmRobot

from rehabkit.api import run_scenario
from rehabkit.core.kinds.interfaces import Context, PlanRequest, Target
from rehabkit.core.run.runner import SetupError
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.core.scenario.models import World
from rehabkit.geometry.solids import path_hits
from rehabkit.models.dh import PoseSpec
from rehabkit.store import StoreError
from rehabkit.testing import group
from tests.conftest import ROOT, SCENARIOS
from tests.located import where

SCENARIO = SCENARIOS / "arm_replay.yaml"
HOME = np.array([0.02, -2.177892, -2.050919, 0.955987, 0.0, -2.04666, 0.963701, 0.0])
WORLD = {"objects": [
    {"name": "tray", "shape": "box", "size": [0.14, 0.26, 0.375], "pose": {"position": [0.42, 0.0, 0.375]}},
    {"name": "cup", "shape": "cylinder", "size": [0.04, 0.05], "pose": {"position": [0.45, -0.12, 0.80]}},
]}


@pytest.fixture(scope="module")
def arm():
    return ArmRobot(ArmConfig(base=PoseSpec(position=(0.10, -0.38, 0.60))))


@pytest.fixture(scope="module")
def replay_run(scenario_run):
    result = scenario_run(SCENARIO)  # the scenario's own run (its scenario test reads the same one)
    return result, json.loads((result.out_dir / "summary.json").read_text()), result.out_dir


def _planner(arm, **cfg):
    ctx = Context(ROOT, np.random.default_rng(0), 0.002, robot=arm, world=World.model_validate(WORLD))
    return BoxAvoidPlanner(BoxAvoidConfig(**cfg), ctx)


def test_planned_motion_follows_the_face_path_within_the_speed_limits(arm):
    planner = _planner(arm)
    goal_pose = arm.fk(HOME)
    goal_pose[:3, 3] = [0.30, -0.32, -0.08]  # beside the tray, above the basket (base frame)
    plan = planner.plan(PlanRequest(0.0, HOME, np.zeros(8), [Target("basket", pose=goal_pose)], arm))
    poly = planner.polylines[-1]
    assert {"tray", "cup"} <= set(plan.details["straight_path_blocked_by"])  # the direct line is blocked
    for o in planner.obstacles:  # the polyline clears every true solid by the gripper margin
        assert not path_hits(poly, o.inflated(0.07)), o.name
    t = np.arange(0.0, plan.trajectory.duration, 0.01)
    q, qd, _ = plan.trajectory.sample(t)
    tip = arm.fk_batch(q)[:, :3, 3]
    # every sampled tip lies on the polyline (distance to the nearest segment)
    a, b = poly[:-1], poly[1:]
    ab = b - a
    u = np.clip(np.einsum("nsk,sk->ns", tip[:, None] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    dist = np.linalg.norm(tip[:, None] - (a[None] + u[..., None] * ab[None]), axis=2).min(axis=1)
    assert dist.max() < 1e-3
    speed = np.linalg.norm(np.diff(tip, axis=0), axis=1) / 0.01
    assert speed.max() <= 0.09 * 1.01  # the configured peak, under the ARM's 9.9 cm/s
    assert np.max(np.abs(qd) / arm.model.limits.velocity) <= 0.9 + 1e-6
    end = arm.fk(plan.trajectory.sample([plan.trajectory.duration])[0][0])
    np.testing.assert_allclose(end, goal_pose, atol=1e-9)
    assert q[:, 0] == pytest.approx(HOME[0])  # the lift keeps its height


def test_position_only_targets_keep_the_gripper_orientation(arm):
    planner = _planner(arm)
    goal = np.eye(4)
    goal[:3, 3] = [0.30, -0.32, -0.08]
    plan = planner.plan(PlanRequest(0.0, HOME, np.zeros(8), [Target("p", pose=goal, position_only=True)], arm))
    q, _, _ = plan.trajectory.sample(np.linspace(0, plan.trajectory.duration, 200))
    rots = arm.fk_batch(q)[:, :3, :3]
    assert np.abs(rots - arm.fk(HOME)[:3, :3]).max() < 1e-6


def test_an_unreachable_or_buried_target_is_a_clear_planning_error(arm):
    from rehabkit.core.kinds.interfaces import PlanningError

    planner = _planner(arm)
    inside = arm.fk(HOME)
    inside[:3, 3] = [0.32, 0.38, 0.0]  # inside the tray (base frame)
    with pytest.raises(PlanningError) as refused:
        planner.plan(PlanRequest(0.0, HOME, np.zeros(8), [Target("t", pose=inside)], arm))
    cause = refused.value.__cause__  # (the path planner's: which end lies where)
    assert (refused.value.target, cause.end, cause.obstacle) == ("t", "goal", "tray")
    far = arm.fk(HOME)
    far[:3, 3] = [1.5, 0.0, 0.3]
    with pytest.raises(PlanningError) as unreachable:
        planner.plan(PlanRequest(0.0, HOME, np.zeros(8), [Target("far", pose=far)], arm))
    # the target named, and the arm's own reach the cause (no obstacle's: the path planner's error would be it)
    assert (unreachable.value.target, unreachable.value.__cause__) == ("far", None)


@pytest.mark.xdist_group(group("arm_replay.yaml"))
def test_the_scenario_records_replays_and_draws_it(replay_run):
    result, summary, out = replay_run
    assert result.passed, result.failures
    m = summary["metrics"]
    assert summary["passed"]  # as written to summary.json
    assert m["replay_position_error_m"] < 1e-3 and m["contact_steps"] == 0 and m["max_tip_speed_m_s"] < 0.099
    replay = summary["plans"][-1]
    assert {"tray", "cup"} <= set(replay["straight_path_blocked_by"]) and replay["obstacle_merges"] >= 1
    texts = [n["text"] for n in summary["notes"]]
    assert any("patch 3: target stored" in x for x in texts) and any("sequence of 3 actions stored" in x for x in texts)
    text = subprocess.run([shutil.which("rerun"), "rrd", "print", str(out / "run.rrd")], capture_output=True,
                          text=True, timeout=120).stdout
    for entity in ("/world/scene/tray", "/world/scene/cup", "/world/scene/basket", "/world/plan/path",
                   "/world/plan/waypoints", "/world/end_effector_path"):
        assert entity in text, entity


@pytest.mark.xdist_group(group("arm_replay.yaml"))
def test_patches_persist_into_the_next_run(replay_run):
    """A later session (a new run, same store) replays patch 3 straight from the menu."""
    _, _, out = replay_run
    store = out / "patches.sqlite"
    keys = [{"at": 0.5, "key": "P"}, {"at": 1.0, "key": "3"}]
    r = run_scenario(SCENARIO, {"controller.store": str(store), "controller.keys": keys, "duration": 30.0})
    m = r.metrics
    assert m["replays"] == 1 and m["replay_failures"] == 0 and m["patches_stored"] == 0
    assert m["replay_position_error_m"] < 1e-3 and m["contact_steps"] == 0


def test_key_timeline_errors_name_the_file_line_key_and_menu(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {SCENARIO}\ncontroller:\n  type: arm-keypad\n  keys:\n"
                   "    - {at: 0.5, key: J}\n    - {at: 1.0, key: x+, hold_s: 2}\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(bad)
    (d,) = err.value.diagnostics  # at the offending press (x+ is not a key of the JOINT menu)
    assert (d.mark.file, d.mark.line, d.mark.col, d.path) == (str(bad), 6, 22, "controller.keys.1.key")
    with pytest.raises(ScenarioError) as short:  # a store held 1 s (hold it 2 s to store)
        load_scenario(SCENARIO, {"controller.keys": [{"at": 0.5, "key": "R"}, {"at": 1.0, "key": "3"},
                                                     {"at": 1.5, "key": "store", "hold_s": 1.0}]})
    assert where(short.value) == [(24, 23, "controller.keys.2.key")]


def test_a_foreign_store_is_refused_and_left_untouched(tmp_path):
    bad = tmp_path / "notes.sqlite"
    bad.write_bytes(b"not a database, somebody's notes" * 100)
    before = bad.read_bytes()
    with pytest.raises(SetupError) as refused:
        run_scenario(SCENARIO, {"controller.store": str(bad), "duration": 1.0})
    assert [d.path for d in refused.value.diagnostics] == ["controller.type"]  # (the keypad's, refused as it is built)
    assert isinstance(refused.value.__cause__.__cause__, StoreError) and refused.value.__cause__.__cause__.path == bad
    assert bad.read_bytes() == before


def test_a_run_that_writes_no_outputs_keeps_its_fresh_store_in_memory(tmp_path, monkeypatch):
    """``store: run`` without an output folder (a run in a test, a notebook): the patch is stored and recalled in
    that run's store, and nothing is written where the run was started (it once made ./out/patches.sqlite)."""
    monkeypatch.chdir(tmp_path)
    keys = [{"at": 0.2, "key": "R"}, {"at": 0.5, "key": "3"}, {"at": 1.0, "key": "store", "hold_s": 2.5}]
    r = run_scenario(SCENARIO, {"controller.keys": keys, "world.objects": [], "duration": 4.0})
    assert any(n["text"].startswith("keypad: patch 3: target stored at") for n in r.summary["notes"])
    assert list(tmp_path.iterdir()) == []


def test_fold_and_unfold_are_preprogrammed_and_any_key_stops_a_motion(tmp_path):
    keys = [{"at": 0.5, "key": "fold"}, {"at": 20.0, "key": "unfold"}, {"at": 22.0, "key": "J"}]
    r = run_scenario(SCENARIO, {"controller.keys": keys, "world.objects": [], "duration": 25.0,
                                "controller.store": str(tmp_path / "patches.sqlite")})  # not ./out (runs here share it)
    q = r.trace.q
    k_folded = int(19.5 / 0.002)
    np.testing.assert_allclose(np.degrees(q[k_folded, 1:7]), [0.0, -170.0, 150.0, 0.0, 20.0, 0.0], atol=0.1)
    texts = [n["text"] for n in r.summary["notes"]]
    assert any(t.startswith("keypad: fold:") for t in texts)
    assert any("'J' stops the unfold" in t for t in texts)
    moved_after_stop = np.abs(np.diff(q[int(22.6 / 0.002):, 1:7], axis=0)).max()
    assert moved_after_stop < 1e-5  # held where the key press stopped it
    assert r.metrics["max_velocity_ratio"] < 1.0


def test_cartesian_mode_moves_along_the_axes_and_keeps_the_gripper_orientation(arm, tmp_path):
    keys = [{"at": 0.2, "key": "C"}, {"at": 0.5, "key": "y-", "hold_s": 2.0}, {"at": 3.0, "key": "z-", "hold_s": 2.0},
            {"at": 5.5, "key": "yaw+", "hold_s": 2.0}, {"at": 8.0, "key": "x+", "hold_s": 6.0}]
    r = run_scenario(SCENARIO, {"controller.keys": keys, "duration": 14.5,
                                "controller.store": str(tmp_path / "patches.sqlite")})
    assert not r.summary["safety"]["events"] and r.metrics["max_velocity_ratio"] < 0.95  # jogs slow, never trip
    poses = arm.fk_batch(r.trace.q)
    k = lambda t: int(t / 0.002)  # noqa: E731
    start, after_y, after_z = poses[k(0.4)], poses[k(2.95)], poses[k(5.45)]
    np.testing.assert_allclose(after_y[:3, 3] - start[:3, 3], [0, -0.10, 0], atol=2e-3)  # 5 cm/s for 2 s
    down = after_z[:3, 3] - after_y[:3, 3]
    assert np.abs(down[:2]).max() < 1e-3 and -0.102 < down[2] < -0.05  # along z only (slowed near the limits)
    turn = np.degrees(np.arccos(np.clip((np.trace(poses[: k(5.45)][:, :3, :3] @ start[:3, :3].T, axis1=1, axis2=2)
                                          - 1) / 2, -1, 1)))
    assert turn.max() < 0.2  # translation jogs keep the orientation (to the servo's tracking error)
    yawed = poses[k(7.95)][:3, :3] @ after_z[:3, :3].T
    assert np.degrees(np.arccos((np.trace(yawed) - 1) / 2)) == pytest.approx(30.0, abs=0.5)  # 15 deg/s for 2 s
    np.testing.assert_allclose(poses[k(7.95)][:3, 3], after_z[:3, 3], atol=2e-3)  # turning in place
    # stretching out along x+ ends at the edge of the workspace with a message, not a trip
    assert any("'x+': the arm can go no further" in n["text"] for n in r.summary["notes"])
