"""A run's state is its session's: the Assembly is the same after a run, a session snapshotted at a step and
restored runs on bit for bit, a learning environment's reset restores instead of building, and a replay forks a
recorded run at a time."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from rehabkit.core.kinds.backend import Backend, NotRestorableError
from rehabkit.core.run.loop import run_loop
from rehabkit.core.run.runner import Runner
from rehabkit.core.run.snapshot import SnapshotMismatchError, restore, snapshot
from rehabkit.core.scenario.loader import load_scenario
from tests.conftest import SCENARIOS


def _fingerprint(value, depth: int = 0, seen: set | None = None):
    """What a value holds, as plain data: arrays by their bytes, records by their fields, settings by their dump; the
    plugins and the backend by their type alone (what they change while a run goes is the session's)."""
    seen = set() if seen is None else seen
    if isinstance(value, (type(None), bool, int, float, str)):
        return value
    if isinstance(value, np.ndarray):
        return ("array", value.shape, value.tobytes())
    if id(value) in seen or depth > 6:
        return ("seen", type(value).__name__)
    seen.add(id(value))
    if hasattr(value, "model_dump"):
        return value.model_dump(mode="json")
    if isinstance(value, dict):
        return {str(k): _fingerprint(v, depth + 1, seen) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_fingerprint(v, depth + 1, seen) for v in value]
    if dataclasses.is_dataclass(value):
        return {f.name: _fingerprint(getattr(value, f.name), depth + 1, seen) for f in dataclasses.fields(value)}
    return ("object", type(value).__name__)


def _assembly(a) -> dict:
    fields = {f.name: getattr(a, f.name) for f in dataclasses.fields(a)}
    for name in ("sensors", "backend", "planner", "event_planners", "controller", "patient", "robot", "registry",
                 "extensions", "loaded"):
        fields.pop(name)
    return {"scenario": a.loaded.source.data, "settings": a.sc.model_dump(mode="json"),
            "limits": _fingerprint(a.robot.model.limits), **_fingerprint(fields)}


def test_a_run_leaves_its_assembly_as_it_was_built():
    """A run that trips the safety layer (a yield under the force limit), says notes and plans: everything it changed
    is the session's — the Assembly (limits, targets, the safety layer's set-up, the context, the settings) is equal
    field by field before and after."""
    runner = Runner(load_scenario(SCENARIOS / "safety" / "hit_force.yaml",
                                  {"safety.reactions": {"interaction-force": {"type": "yield"}}, "expect": None}))
    session = runner.start()
    before = _assembly(session.setup)
    run_loop(session)
    assert session.safety.tripped and session.safety.events[0].rule == "interaction-force"  # (it did change things)
    assert session.force is not None and len(session.plans) >= 1
    assert _assembly(session.setup) == before
    assert runner.setup.safety.layer().events == []  # a layer made from the set-up stands at the start


def test_a_session_restored_at_a_step_runs_on_bit_for_bit():
    """The HIT with the MyoArm strapped in (an embodied patient whose body is in the scene, muscles, noise streams):
    snapshot at 40 %, run to the end, restore, run again — the same trace to the last bit, the same events."""
    session = Runner(load_scenario(SCENARIOS / "hit_myoarm.yaml", {"duration": 1.0, "expect": None})).start()
    n = session.setup.schedule.steps
    run_loop(session, k_to=int(0.4 * n))
    snap = snapshot(session)
    run_loop(session)
    first = session.trace.trimmed(session.loop.k)
    q, tau, tau_h = first.q.copy(), first.tau.copy(), session.setup.backend.data.act.copy()
    events = [(e.t, e.rule) for e in session.safety.interventions]
    assert restore(session, snap) == []  # (its own: no plugin starts afresh)
    assert session.loop.k == snap.k
    run_loop(session)
    again = session.trace.trimmed(session.loop.k)
    assert np.array_equal(again.q, q) and np.array_equal(again.tau, tau)
    assert np.array_equal(session.setup.backend.data.act, tau_h)  # the muscles' activations too
    assert [(e.t, e.rule) for e in session.safety.interventions] == events


def test_a_robots_backend_refuses_a_snapshot_by_its_type():
    class Link(Backend):  # (a robot's backend: not restorable, the default)
        timestep = 0.001

        def reset(self, q0): ...
        def state(self): ...
        def command(self, tau): ...
        def step(self, n=1): ...

    with pytest.raises(NotRestorableError) as refused:
        Link().run_state()
    assert refused.value.backend == "Link"
    from rehabkit.canopen.backend import CanopenBackend
    from rehabkit.hardware.backend import HardwareBackend
    from rehabkit.sim.mujoco import MujocoBackend

    assert (MujocoBackend.restorable, HardwareBackend.restorable, CanopenBackend.restorable) == (True, False, False)


def test_a_snapshot_goes_only_into_a_session_of_the_same_scene_and_length():
    session = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", {"duration": 1.0, "expect": None})).start()
    snap = snapshot(session)
    other = Runner(load_scenario(SCENARIOS / "hit_roundtrip.yaml", {"duration": 2.0, "expect": None})).start()
    with pytest.raises(SnapshotMismatchError) as refused:
        restore(other, snap)
    assert refused.value.part == "duration"


def test_a_gym_reset_restores_the_start_and_gives_the_fresh_episode_bit_for_bit():
    """L-Exos with the MyoArm as an environment (its episodes depend on the seed: the patient's noise): after an
    episode on seed 9, a reset on seed 5 restores the start and re-seeds (no build), and its episode equals a freshly
    built environment's on seed 5, observation by observation; another seed gives another episode."""
    from rehabkit.gym.env import ScenarioEnv

    def episode(env, seed, steps=20):
        obs, info = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        seen, rewards = [obs], []
        for _ in range(steps):
            obs, reward, *_ = env.step(rng.uniform(-0.3, 0.3, env.action_space.shape))
            seen.append(obs)
            rewards.append(reward)
        return np.concatenate(seen), rewards, info

    env = ScenarioEnv(SCENARIOS / "lexos_myoarm.yaml")
    episode(env, 9)
    obs, rewards, info = episode(env, 5)
    assert info["reset"] == "restored" and info["seed"] == 5
    fresh_obs, fresh_rewards, _ = episode(ScenarioEnv(SCENARIOS / "lexos_myoarm.yaml"), 5)
    assert np.array_equal(obs, fresh_obs) and rewards == fresh_rewards
    other, _, _ = episode(env, 6)
    assert not np.array_equal(other, obs)


def test_a_replay_forked_at_a_time_keeps_the_recorded_session_until_then(tmp_path):
    """HIT round trip recorded, then replayed from 3 s on with softer gains: up to 3 s the replay's joints are the
    recording's bit for bit, after it they part; the replay says where it forked."""
    from rehabkit.rehab.replay import replay

    loaded = load_scenario(SCENARIOS / "hit_roundtrip.yaml", {"duration": 5.0})
    original = Runner(loaded, out_dir=tmp_path / "run").run()
    rep = replay(tmp_path / "run", ["controller.kp=[90, 90, 15, 18, 1.6, 1.8]"], tmp_path / "fork", fork_at=3.0)
    k = rep.fork["step"]
    assert k == 3000 and rep.fork["fresh"] == ["controller"]  # (its settings changed: it starts afresh)
    q0, q1 = original.trace.q, rep.result.trace.q
    assert np.array_equal(q1[:k], q0[:k])
    assert np.abs(q1[k + 200:] - q0[k + 200:]).max() > 1e-4
    summary = json.loads((tmp_path / "fork" / "summary.json").read_text())
    assert summary["metrics"]["sim_time_s"] == pytest.approx(5.0, abs=0.002)
