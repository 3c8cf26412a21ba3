"""The COMAN juggling scenario, shortened to two throws: the summary and what Rerun shows."""

import shutil
import subprocess

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.testing import group
from tests.conftest import SCENARIOS


@pytest.mark.xdist_group(group("coman_juggling.yaml"))
def test_every_throw_is_released_caught_and_drawn(scenario_run):
    r = scenario_run(SCENARIOS / "coman_juggling.yaml")  # the scenario test's own run (ten throws), shared
    m, s = r.metrics, r.summary
    assert m["throws_released"] == 10 and m["throws_crossed"] == 10
    assert m["catch_max_error_m"] < 0.05 and m["com_margin_min_m"] > 0 and m["feet_slip_max_mm"] < 2.0
    assert [a["action"] for a in s["actions"]] == ["grasp", "release"] * 10
    throws = [th for plan in s["plans"] for th in plan.get("throws", [])]
    assert len(throws) >= 10
    catch = np.array([0.50, -0.16, -0.08])
    for th in throws:  # the generator's own prediction of the crossing, from the planned release
        assert np.linalg.norm(np.array(th["predicted_crossing_m"]) - catch) < 0.02
        assert th["generation_us"] < 20_000
    assert s["reports"]["ball"].startswith("10 of 10 throws crossed the catch plane")
    text = subprocess.run([shutil.which("rerun"), "rrd", "print", str(r.out_dir / "run.rrd")], capture_output=True,
                          text=True, timeout=120).stdout
    for entity in ("/world/bodies/Waist", "/world/bodies/RSoftHand", "/world/bodies/ball", "/world/planner/parabola_1",
                   "/world/planner/catch_zone", "/world/plan/path", "/world/end_effector_path"):
        assert entity in text, entity


def test_a_plan_with_an_unknown_scene_action_is_refused_not_crashed(monkeypatch):
    from rehabkit_plugins.planners import throw_lwlr

    original = throw_lwlr.ThrowPlanner.plan

    def plan_with_teleport(self, request):
        plan = original(self, request)
        plan.actions.append((0.1, "teleport", "ball"))
        return plan

    monkeypatch.setattr(throw_lwlr.ThrowPlanner, "plan", plan_with_teleport)
    r = run_scenario(SCENARIOS / "coman_juggling.yaml", {"task.sequence": ["catch"], "duration": 0.3})
    ev = r.summary["safety"]["events"]
    assert ev and ev[0]["rule"] == "plan" and ev[0]["data"]["actions"] == ["teleport"]
    assert r.summary["actions"] == []
