"""A robot's own dynamics — its drives' damping and Coulomb friction as its URDF declares them — simulated as
written and known to the model the controllers use; where a run tracks badly, it says why.

tests/data/drag3.urdf declares what the xArm7's URDF (example-robot-data) declares: damping 10, 5 and 2 N·m·s/rad,
friction 1 N·m, and a wrist 1.4e-4 kg·m² about its axis."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from rehabkit.api import run_scenario
from rehabkit.cli.main import main
from rehabkit.core.kinds.context import Context
from rehabkit.core.plugins.registry import default_registry
from rehabkit.core.safety.stopping import stable_gains
from rehabkit.core.scenario.models import World
from rehabkit.sim.scene import build_scene

DATA = Path(__file__).parent / "data"
SCENARIO = {
    "name": "drag3", "robot": {"type": "urdf", "file": str(DATA / "drag3.urdf"), "ee_frame": "tool"},
    "planner": {"type": "multi-cubic", "segment_durations": [1.5]},
    "controller": {"type": "joint-pd", "gains": "auto", "feedforward": "inverse-dynamics"},
    "task": {"targets": [{"name": "A", "joints": [-20, -30, -60]}, {"name": "B", "joints": [20, 10, 60]}]},
    "duration": 2.0,
}


@pytest.fixture(scope="module")
def drag3():
    info = default_registry().get("robot", "urdf")
    config = info.config.model_validate(SCENARIO["robot"])
    return info.factory(config, Context(DATA, np.random.default_rng(0), 0.001))


def _scenario(tmp_path: Path, **changes) -> Path:
    path = tmp_path / "drag3.yaml"
    path.write_text(yaml.safe_dump({**SCENARIO, **changes}, sort_keys=False))
    return path


def test_the_urdfs_damping_and_friction_are_the_models_and_the_friction_is_dry(drag3):
    known = drag3.model.dissipation
    assert known.damping.tolist() == [10.0, 5.0, 2.0] and known.friction.tolist() == [1.0, 1.0, 1.0]
    # the feedforward's loss at 30 °/s on the wrist: 2 · 0.52 + 1 (friction, fully in above 1 °/s)
    assert known.torque(np.radians([0, 0, 30]))[2] == pytest.approx(2 * np.radians(30) + 1.0, rel=1e-6)

    def wrist_after(torque: float) -> tuple[float, float]:
        spec = build_scene(drag3.model, World(floor=False), 0.001)
        model = spec.compile()
        model.opt.gravity[:] = 0.0
        data = mujoco.MjData(model)
        data.qfrc_applied[2] = torque
        mujoco.mj_step(model, data, nstep=500)
        return np.degrees(data.qpos[2]), np.degrees(data.qvel[2])

    # below its friction the light wrist stays put (MuJoCo's default softness: it crept at 24 °/s) ...
    moved, speed = wrist_after(0.9)
    assert abs(moved) < 0.1 and abs(speed) < 0.2
    # ... above it, it turns, against its damping: (1.5 − 1) / 2 rad/s = 14.3 °/s
    moved, speed = wrist_after(1.5)
    assert speed == pytest.approx(np.degrees(0.25), rel=0.05) and moved > 5.0


def test_gains_auto_with_the_inverse_dynamics_feedforward_tracks_a_robot_with_its_own_drag(tmp_path):
    result = run_scenario(_scenario(tmp_path))
    assert result.metrics["tracking_rms_deg"] < 0.1 and result.metrics["task_complete"] == 1.0
    assert "tracking" not in result.summary
    # gravity alone leaves the drag to the gains: the wrist lags, and the run says which joint and why
    lagging = run_scenario(_scenario(tmp_path, controller={"type": "joint-pd", "gains": "auto",
                                                           "feedforward": "gravity"}))
    why = lagging.summary["tracking"]
    assert lagging.metrics["tracking_rms_deg"] > 1.0
    assert why["joint"] == "roll" and why["unit"] == "deg" and 2.0 < why["rms"] < 6.0
    assert len(why["causes"]) == 1 and "gains are low" in why["causes"][0]
    assert "its drive declares friction 1 N·m and damping 2 N·m·s/rad, left to the gains" in why["causes"][0]


def test_a_run_that_clips_a_joints_torque_says_so_and_validate_says_it_first(tmp_path, capsys):
    path = _scenario(tmp_path, robot={**SCENARIO["robot"], "limits": {"pitch": {"effort": 1.5}}})
    assert main(["validate", str(path)]) == 0
    said = capsys.readouterr().out
    line = next(x for x in said.splitlines() if x.strip().startswith("PLAN") and "pitch" in x)
    assert "over its 1.5 N·m effort limit" in line and "against gravity" in line
    result = run_scenario(path)
    why = result.summary["tracking"]
    assert why["joint"] == "pitch" and any("1.5 N·m limit" in c for c in why["causes"])


def test_a_joints_own_damping_lets_the_hold_be_stiffer_on_a_light_joint():
    # the wrist alone: kd capped at half its inertia per period (0.07 N·m·s/rad); its 2 N·m·s/rad of damping
    # weighs as 2e-3 kg·m² over a 1-ms period
    kp, kd = stable_gains(np.array([400.0]), np.array([40.0]), np.array([1.4e-4]), 1e-3)
    assert kd[0] == pytest.approx(0.07)
    kp2, kd2 = stable_gains(np.array([400.0]), np.array([40.0]), np.array([1.4e-4]), 1e-3, np.array([2.0]))
    assert kd2[0] == pytest.approx(0.5 * (1.4e-4 + 2e-3) / 1e-3) and kp2[0] > 10 * kp[0]


def test_a_stop_that_could_not_hold_the_robot_is_said():
    """An arm whose drives can't hold its weight falls through a 'held' stop: the terminal says what the stop did."""
    from rehabkit.cli.run_report import _stop_outcome

    held = {"stop_category": 2.0, "stop_time_s": 0.12, "joints_in_range": 1.0, "stop_distance_deg": 0.4}
    assert _stop_outcome(held) == [] and _stop_outcome({}) == []
    fell = {"stop_category": 2.0, "stop_time_s": None, "joints_in_range": 0.0, "stop_distance_deg": 68.5}
    (line,) = _stop_outcome(fell)
    assert line.startswith("  STOP    the robot did not come to rest and left the joints' ranges") and "68.5°" in line
    # a run that ended as its stop began (a link's fault: the robot side holds it) did not fail to hold it: said so
    (ended,) = _stop_outcome({"stop_category": 2.0, "stop_time_s": None, "joints_in_range": 1.0,
                              "stop_distance_deg": 0.0})
    assert "did not come to rest" not in ended and "did not move after the trigger" in ended
