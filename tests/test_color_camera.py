"""The colour camera: detection, 3-D accuracy, misses, and driving a plan."""

import mujoco
import numpy as np
import pytest

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.testing import group
from tests.conftest import SCENARIOS

LEXOS = SCENARIOS / "lexos_reaching.yaml"


@pytest.fixture(scope="module")
def scene():
    runner = Runner(load_scenario(LEXOS))
    runner.build()
    runner.backend.reset(np.radians([20, -45, 0, -70]))
    return runner


def _show(scene, position):
    b = scene.backend
    b.move_object("ball", np.asarray(position, float))
    mujoco.mj_forward(b.model, b.data)
    return scene.sensors["camera"].read(0.0, None, None, b)


def test_ball_positions_are_estimated_within_a_couple_of_centimetres(scene, rng):
    base = scene.robot.model.base_pose
    errors, hidden = [], 0
    for _ in range(40):
        world = rng.uniform([0.4, -0.6, 0.75], [0.9, 0.6, 1.0])
        reading = _show(scene, world)
        assert reading["image"].shape == (480, 640, 3) and reading["image"].dtype == np.uint8
        if reading.get("occluded"):  # under the arm: a miss, not a guess
            hidden += 1
            continue
        assert reading["detected"] == 1.0
        expected_base = base[:3, :3].T @ (world - base[:3, 3])
        errors.append(np.linalg.norm(reading["target_position"] - expected_base))
    assert hidden <= 6 and len(errors) >= 34
    assert np.mean(errors) < 0.015 and np.max(errors) < 0.025


def test_a_ball_half_hidden_under_the_hand_is_reported_as_occluded(scene):
    reading = _show(scene, [0.54, -0.06, 0.92])  # just below the hand, seen from above
    assert reading.get("occluded") == 1.0 and reading["target_position"] is None


def test_no_ball_in_view_is_a_miss_not_a_guess(scene):
    reading = _show(scene, [0.6, 2.5, 0.8])
    assert reading["detected"] == 0.0 and reading["target_position"] is None


def test_pinhole_model_matches_mujocos_projection(scene):
    cam = scene.sensors["camera"]
    b = scene.backend
    pos, rot, fovy = b.camera_pose("overhead")
    world = np.array([0.7, 0.2, 0.85])
    p = cam.intrinsics(fovy) @ (rot.T @ (world - pos))
    u, v = p[:2] / p[2]
    reading = _show(scene, world)
    assert np.hypot(*(reading["pixel"] - [u, v])) < 0.5  # the ball's centre where the pinhole says


@pytest.mark.xdist_group(group("lexos_reaching.yaml"))
def test_move_events_drive_replanning_through_the_camera(scenario_run):
    r = scenario_run(LEXOS)  # the scenario's own run (its scenario test reads the same one)
    triggers = [(e["t"], e["trigger"]) for e in r.summary["events"]]
    assert triggers[:2] == [(4.0, "at 4.0"), (4.2, "ball moved")]  # seen, held for 2 readings at 10 Hz
    assert r.summary["plans"][1]["t"] == 4.2 and r.metrics["camera_error_max_mm"] < 25
