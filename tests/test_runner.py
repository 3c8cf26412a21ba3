"""Whole runs: tracking, determinism, events, safety stops, contacts, outputs."""

import json
import shutil
import subprocess

import numpy as np
import pytest

from rehabkit.api import run_scenario
from rehabkit.core.kinds.interfaces import Controller, StrictModel
from rehabkit.core.log.safety_log import check
from rehabkit.core.run.runner import Runner, SetupError
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.plugin import SensorName
from tests.conftest import SCENARIOS, registry_with
from tests.located import suggested

HIT = SCENARIOS / "hit_roundtrip.yaml"


@pytest.fixture(scope="module")
def hit_run(scenario_run):
    return scenario_run(HIT)  # the scenario's own run (its scenario test reads the same one)


def test_hit_round_trip_tracks_and_reaches_every_via_point(hit_run, hit):
    m = hit_run.metrics
    assert hit_run.passed
    assert m["tracking_rms_deg"] < 0.5 and m["tracking_max_deg"] < 1.5
    assert m["final_position_error_m"] < 0.005
    tr = hit_run.trace
    qa = np.radians([0, 90, 90, 30, -90, 90])
    b = hit.fk(qa)
    b[:3, 3] = [-0.45, -0.1, -0.3]
    for t_via, goal in ((2.0, b[:3, 3]), (4.0, hit.fk(qa)[:3, 3]), (6.0, b[:3, 3]), (8.0, hit.fk(qa)[:3, 3])):
        k = int(round(t_via * 1000))
        assert np.linalg.norm(hit.fk(tr.q[k])[:3, 3] - goal) < 0.005, t_via  # measured hand, not the reference
    assert np.abs(tr.qd[-1]).max() < 0.01  # at rest at E


def test_same_seed_same_run(hit_run):
    again = run_scenario(HIT)
    np.testing.assert_array_equal(again.trace.q, hit_run.trace.q)
    np.testing.assert_array_equal(again.trace.tau, hit_run.trace.tau)


def test_outputs_are_complete_and_nothing_half_written(hit_run):
    out = hit_run.out_dir
    assert sorted(p.name for p in out.iterdir()) == ["run.rrd", "safety_log.jsonl", "scenario.yaml", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["passed"] and summary["seed"] == 0 and summary["metrics"]["real_time_factor"] > 0  # (its speed:
    # a benchmark's figure, not an assertion)


def test_rrd_holds_geometry_poses_paths_and_series(hit_run):
    rerun = shutil.which("rerun")
    text = subprocess.run([rerun, "rrd", "print", str(hit_run.out_dir / "run.rrd")], capture_output=True,
                          text=True, timeout=120).stdout
    for entity in ("/world/bodies/elbow_2_link/elbow_2_g0", "/world/bodies/wrist_2_link - data columns: [Transform3D",
                   "/world/plan/path", "/world/targets", "/world/end_effector_path", "/tracking_error_deg",
                   "/sensors/encoders/position_deg", "/world/scene/floor"):
        assert entity in text, entity


def test_replan_that_cannot_be_planned_holds_the_robot():
    r = run_scenario(HIT, {"task.events": [{"at": 1.0, "action": "replan", "sequence": ["B", "C"]}], "expect": None})
    (ev,) = r.summary["safety"]["events"]
    assert ev["rule"] == "plan" and ev["t"] == 1.0  # too few segment durations for the replan's via points:
    assert ev["data"]["cause"] == "segment-count" and ev["data"]["setting"] == "segment_durations"
    assert r.summary["metrics"]["sim_time_s"] == pytest.approx(1.5)  # held for stop_after_s, then ended


def test_timed_replan_then_stop():
    r = run_scenario(HIT, {"task.events": [{"at": 1.0, "action": "replan"}, {"at": 3.5, "action": "stop"}],
                           "planner.start_from_current": True, "planner.segment_durations": [2, 2, 2, 2, 2],
                           "expect": None})
    assert [(e["action"], e["t"]) for e in r.summary["events"]] == [("replan", 1.0), ("stop", 3.5)]
    assert not r.summary["safety"]["events"] and r.summary["metrics"]["sim_time_s"] == pytest.approx(3.5)
    tr = r.trace
    assert np.abs(tr.q_ref[1000] - tr.q[1000]).max() < np.radians(0.5)  # the new plan starts where the arm is


def test_reached_event_fires_near_the_target():
    r = run_scenario(HIT, {"task.events": [{"reached": "B", "tolerance_m": 0.01, "action": "stop"}], "expect": None})
    (ev,) = r.summary["events"]
    assert ev["trigger"] == "reached B" and 1.0 < ev["t"] < 2.1
    assert r.summary["metrics"]["sim_time_s"] == pytest.approx(ev["t"], abs=0.002)


def test_too_fast_plan_is_rejected_before_the_robot_moves(tmp_path):
    """A first plan breaking the robot's own limit is refused before anything runs, as one breaking a narrowed limit
    is, and as validate refuses it: located at the planner, the breach as fields, no run folder."""
    with pytest.raises(SetupError) as err:
        run_scenario(HIT, {"planner.segment_durations": [0.2, 0.2, 0.2, 0.2]}, tmp_path / "out")
    breach = err.value.breach
    assert breach.quantity == "velocity" and breach.value > breach.limit > 0 and breach.at_s is not None
    assert err.value.diagnostics[0].path.startswith("planner") and not (tmp_path / "out" / "summary.json").exists()


def test_obstacle_in_the_way_is_reported_as_contact():
    box = {"name": "table", "shape": "box", "size": [0.1, 0.1, 0.02], "pose": {"position": [0.45, 0.1, 0.96]}}
    r = run_scenario(HIT, {"world.objects": [box]})
    assert r.metrics["contact_steps"] > 0 and not r.passed


class _BadConfig(StrictModel):
    fail_at: float = 0.5
    mode: str = "nan"


class _BadController(Controller):
    """A good joint PD that returns NaN (or raises, or one torque too few) after a while."""

    def __init__(self, config, context):
        from rehabkit_plugins.controllers.joint_pd import JointPD, JointPDConfig

        self.config, self.n = config, context.robot.model.dof
        self.good = JointPD(JointPDConfig(kp=[900, 900, 150, 180, 16, 18], kd=[45, 45, 8, 9, 0.8, 0.9]), context)

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        if t < self.config.fail_at:
            return self.good.compute(t, q, qd, q_ref, qd_ref, qdd_ref)
        if self.config.mode == "raise":
            raise ZeroDivisionError("gain schedule broke")
        if self.config.mode == "short":  # one torque short
            return np.zeros(self.n - 1)
        return np.full(self.n, np.nan)


@pytest.fixture(scope="module")
def bad_registry():
    return registry_with("controller", "bad", _BadConfig, _BadController)


@pytest.mark.parametrize("mode, rule", [("nan", "non-finite"), ("raise", "plugin-error"), ("short", "plugin-error")])
def test_broken_controller_stops_the_robot_and_the_logs_say_why(tmp_path, bad_registry, mode, rule):
    r = run_scenario(HIT, {"controller": {"type": "bad", "mode": mode}}, out_dir=tmp_path, registry=bad_registry)
    (ev,) = r.summary["safety"]["events"]
    assert ev["rule"] == rule and ev["t"] == pytest.approx(0.5, abs=0.002)
    if rule == "plugin-error":  # whose bug, and what it did: raised, or returned torques that do not fit
        assert {k: ev["data"][k] for k in ("plugin", "kind", "package", "error")} == \
            {"plugin": "bad", "kind": "controller", "package": "tests", "error": {"raise": "ZeroDivisionError",
                                                                                 "short": "ValueError"}[mode]}
        assert ev["data"].get("returned_shape") == ([5] if mode == "short" else None)
    assert not r.passed and r.summary["metrics"]["sim_time_s"] == pytest.approx(1.0, abs=0.01)  # stop_after_s = 0.5
    assert np.all(np.isfinite(r.trace.tau))
    after = r.trace.qd[int(0.9 * 1000):]
    assert np.abs(after).max() < 0.5  # held, not flailing
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["safety"]["events"][0]["rule"] == rule and (tmp_path / "run.rrd").exists()


def test_no_rrd_when_logging_is_off(tmp_path):
    r = run_scenario(HIT, {"logging.rrd": False, "duration": 0.5, "expect": None}, out_dir=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["safety_log.jsonl", "scenario.yaml", "summary.json"]
    assert r.passed


def test_a_run_that_dies_after_its_loop_leaves_no_half_written_file(tmp_path, monkeypatch):
    from rehabkit.core.log.rerun_log import RerunLog

    full = OSError("disk full")

    def broken_flush(self):
        raise full

    monkeypatch.setattr(RerunLog, "flush", broken_flush)
    with pytest.raises(OSError) as err:
        run_scenario(HIT, {"duration": 0.2, "expect": None}, out_dir=tmp_path)
    assert err.value is full  # the writer's own error, not another
    # no half-written recording or summary; the safety log stays, as it stood (the robot moved: its audit trail is
    # kept, without its closing record, as a killed run's is), and the scenario it ran (written whole as it opened)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["safety_log.jsonl", "scenario.yaml"]
    assert not check(tmp_path / "safety_log.jsonl").finished


@pytest.mark.parametrize("error", [ValueError("Value does not fit in specified type"), KeyboardInterrupt()])
def test_a_run_whose_backend_fails_at_its_reset_leaves_no_half_written_file(tmp_path, monkeypatch, error):
    """The recording opens before the robot is reset; a reset that fails (a plugin's bug, Ctrl-C) takes it along — and
    the folder the run made, which it leaves empty (an existing one is left as it was)."""
    from rehabkit.sim.mujoco import MujocoBackend

    def reset(self, q0):
        raise error

    monkeypatch.setattr(MujocoBackend, "reset", reset)
    with pytest.raises(type(error)):
        run_scenario(HIT, {"duration": 0.2, "expect": None}, out_dir=tmp_path)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(type(error)):
        run_scenario(HIT, {"duration": 0.2, "expect": None}, out_dir=tmp_path / "made")
    assert list(tmp_path.iterdir()) == []


def test_spawn_without_a_display_still_writes_the_file(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(UserWarning, match="no display"):
        r = run_scenario(HIT, {"duration": 0.2, "expect": None}, out_dir=tmp_path, spawn=True)
    assert r.passed and (tmp_path / "run.rrd").stat().st_size > 0


def test_summary_lists_each_plans_via_points(hit_run, hit):
    (plan,) = hit_run.summary["plans"]
    assert plan["t"] == 0.0 and plan["duration_s"] == 8.0
    q_b = np.radians(plan["waypoints_deg"][1])
    np.testing.assert_allclose(hit.fk(q_b)[:3, 3], [-0.45, -0.1, -0.3], atol=1e-6)


def test_a_plugin_builds_another_from_the_runs_own_plugins(bad_registry):
    """Context.build (a policy's base controller, any wrapper): from the run's registry — here one only this test's
    registry has — with the settings checked and what is wrong named by setting."""
    from rehabkit.core.run.runner import Runner
    from rehabkit.core.scenario.loader import load_scenario

    a = Runner(load_scenario(HIT, registry=bad_registry), registry=bad_registry).build()
    inner = a.context.build("controller", {"type": "bad", "fail_at": 0.25})
    assert isinstance(inner, _BadController) and inner.config.fail_at == 0.25
    with pytest.raises(ValueError, match=r"controller 'bad': fail_at: Input should be a valid number"):
        a.context.build("controller", {"type": "bad", "fail_at": "soon"})
    with pytest.raises(ValueError) as unknown:
        a.context.build("controller", {"type": "badd"})
    assert (unknown.value.__cause__.kind, unknown.value.__cause__.name) == ("controller", "badd")
    assert suggested(str(unknown.value)) == ["bad"]


class _SensedPDConfig(StrictModel):
    sensor: SensorName = "encoders"
    kp: float = 900.0
    kd: float = 40.0


class _SensedPD(Controller):
    """A joint PD on a named sensor's angles (the encoders), not the simulator's: what a lab's controller does."""

    def __init__(self, config, context):
        self.config, self.context, self.seen = config, context, []

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        r = self.context.reading(self.config.sensor)
        self.seen.append((t, None if r is None else (r.t, r.frame, r.values["position_rad"].copy())))
        angles = q if r is None else r.values["position_rad"]
        return self.config.kp * (q_ref - angles) + self.config.kd * (qd_ref - qd)


def test_a_controller_reads_a_sensor_by_the_name_in_its_settings(tmp_path):
    """Context.reading: the named sensor's latest reading, with its time; a SensorName setting naming no sensor of
    the scenario is refused at that setting, with the nearest name."""
    registry = registry_with("controller", "sensed-pd", _SensedPDConfig, _SensedPD)
    runner = Runner(load_scenario(HIT, {"duration": 0.5, "controller": {"type": "sensed-pd"},
                                        "planner.segment_durations": [2.0] * 4}, registry=registry),
                    registry=registry)
    result = runner.run()
    seen = runner.setup.controller.seen
    assert seen[0][1] is not None  # the encoders read before the first control step (both at k = 0)
    times = np.array([s[0] for s in seen])
    read_at = np.array([s[1][0] for s in seen])
    assert np.all(times - read_at >= -1e-12) and np.all(times - read_at < 2e-3 + 1e-9)  # 500 Hz: at most 2 ms old
    assert seen[-1][1][1] is None  # joint angles: no frame
    step = 2 * np.pi / 65536  # the reading is the encoders' (quantised), not the simulator's angles
    assert np.allclose(np.round(seen[-1][1][2] / step) * step, seen[-1][1][2], atol=1e-12)
    assert result.metrics["safety_events"] == 0
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {HIT}\ncontroller:\n  type: sensed-pd\n  sensor: encoder\n")
    with pytest.raises(ScenarioError) as err:
        Runner(load_scenario(bad, registry=registry), registry=registry).build()
    (d,) = err.value.diagnostics
    assert (d.path, d.mark.line, d.mark.col) == ("controller.sensor", 4, 3)
    assert d.fix == "did you mean 'encoders'? (its sensors: encoders)"


class _BuggyController(Controller):
    def __init__(self, config, context):
        {}["oops"]  # a plugin's own bug

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        return np.zeros_like(q)


def test_a_plugin_that_fails_with_its_own_bug_is_named_at_its_type_exit_2(tmp_path, capsys):
    """Not an internal error of rehabkit's: the plugin, its package and the section (exit 2 from validate)."""
    registry = registry_with("controller", "buggy", _BadConfig, _BuggyController, package="buggy-lab",
                             version="0.3")
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"extends: {HIT}\ncontroller:\n  type: buggy\n")
    with pytest.raises(ScenarioError) as err:
        Runner(load_scenario(bad, registry=registry), registry=registry).build()
    (d,) = err.value.diagnostics
    assert (d.path, d.mark.line) == ("controller.type", 3)
    assert (err.value.provider.package, err.value.provider.version) == ("buggy-lab", "0.3")  # (to report it to)
    assert isinstance(err.value.__cause__, KeyError) and err.value.__cause__.args == ("oops",)


class _YieldingPD(Controller):
    """A PD that deliberately lags its plan by 2° on every joint (as a compliant controller yields), exposing the
    reference it tracks: that one is its own."""

    def __init__(self, config, context):
        self.gravity, self.joint_reference = context.robot.gravity_torque, None

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        self.joint_reference = q_ref - np.radians(2.0)
        return 900 * (self.joint_reference - q) + 45 * (qd_ref - qd) + self.gravity(q)


def test_tracking_is_measured_against_the_plan_and_against_the_controllers_own_reference():
    registry = registry_with("controller", "yielding-pd", _BadConfig, _YieldingPD)
    r = run_scenario(HIT, {"duration": 3.0, "controller": {"type": "yielding-pd"}}, registry=registry)
    m = r.metrics
    assert m["tracking_rms_deg"] > 1.8  # the plan's: the 2° it yields counts as error
    assert m["controller_tracking_rms_deg"] < 0.5 < 1.8 < m["tracking_rms_deg"]  # its own: tracked
    assert r.summary["metric_info"]["controller_tracking_rms_deg"]["unit"] == "deg"
    assert "controller_tracking_rms_deg" not in run_scenario(HIT, {"duration": 0.5}).metrics  # joint-pd has none


def test_a_plan_that_outlasts_the_run_is_warned_of_and_fails_the_run(tmp_path, capsys):
    """segment_durations in milliseconds by mistake: validate warns at the setting with the numbers; the run says the
    task did not finish and exits 1 although its other verdicts pass (an arm that barely moved 'reaches' its goal:
    the last target is the first); a run cut short on purpose says so and passes."""
    from rehabkit.cli.main import main

    p = tmp_path / "ms.yaml"
    p.write_text(f"extends: {SCENARIOS / 'hit_roundtrip.yaml'}\n"
                 "planner: {type: multi-cubic, segment_durations: [3000, 3000, 3000, 3000]}\nduration: 2\n")
    assert main(["validate", str(p)]) == 0
    assert f"PLAN    planner.segment_durations ({p}:2:30): the plan lasts 1.2e+04 s and the run 2 s (duration at " \
           f"{p}:3:1): the task cannot finish — 0.0% of it is run" in capsys.readouterr().out
    assert main(["run", str(p), "--out", str(tmp_path / "run")]) == 1
    said = capsys.readouterr().out
    assert "TASK    incomplete: the plan ends at 1.2e+04 s, the run at 2 s (0.0% of it run)" in said
    verdicts = {w[1]: w[0] for w in map(str.split, said.splitlines()) if w[:1] in (["PASS"], ["FAIL"])}
    assert verdicts and set(verdicts.values()) == {"PASS"}  # (no verdict failed)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["task"]["complete"] is False and summary["metrics"]["task_complete"] == 0
    p.write_text(p.read_text() + "expect: {task_complete: {eq: 0}}\n")  # (a rehearsal of the first seconds)
    assert main(["run", str(p)]) == 0
