"""Scenarios as Gymnasium environments (rehabkit.gym): Gymnasium's own checker on every built-in scenario with a
learning: section, vectorised environments, bit-for-bit episodes from a seed, and dangerous actions ending in a
safety stop."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rehabkit.gym  # noqa: F401  (registers rehabkit/Scenario-v0)
from rehabkit.api import run_scenario
from rehabkit.core.scenario.errors import ScenarioError
from rehabkit.gym.env import ScenarioEnv
from rehabkit.models.policy import Policy
from tests.conftest import SCENARIOS

LEARNING = sorted(p for p in SCENARIOS.glob("*.yaml") if "\nlearning:" in p.read_text())
HIT = SCENARIOS / "hit_roundtrip.yaml"
HIT_LEARNING = {"learning": {"policy_hz": 50}}  # the round trip as an environment, its learning defaults


def test_some_built_in_scenarios_are_environments():
    assert {p.name for p in LEARNING} >= {"lexos_myoarm.yaml", "hit_myoarm.yaml"}


@pytest.mark.filterwarnings("ignore:.*infinity")  # (the joint states have no finite bounds to declare)
@pytest.mark.parametrize("path", LEARNING, ids=[p.stem for p in LEARNING])
def test_gymnasiums_checker_passes(path):
    env = gymnasium.make("rehabkit/Scenario-v0", scenario=str(path))
    check_env(env.unwrapped)
    env.close()


def test_the_same_seed_gives_the_same_episode_bit_for_bit():
    env = ScenarioEnv(SCENARIOS / "hit_myoarm.yaml", {"duration": 1.0, "patient.comfort.max_interaction_force_n": 500})
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (50, env.action_space.shape[0])).astype(np.float32)

    def episode(seed):
        obs, _ = env.reset(seed=seed)
        seen, paid = [obs], []
        for action in actions:
            obs, reward, terminated, truncated, info = env.step(action)
            seen.append(obs)
            paid.append((reward, *info["reward_terms"].values()))
            if terminated or truncated:
                break
        return np.array(seen), np.array(paid), terminated, truncated

    first, again, other = episode(7), episode(7), episode(8)
    assert first[3] and not first[2]  # truncated by the duration, after 50 policy steps of 20 ms
    assert np.array_equal(first[0], again[0]) and np.array_equal(first[1], again[1])
    assert not np.array_equal(first[0], other[0])  # another seed: another person's noise
    env.close()


ACTIONS = {"residual (a person strapped in)": (SCENARIOS / "hit_myoarm.yaml", {}),
           "torque": (HIT, {**HIT_LEARNING, "learning.action": {"kind": "torque", "scale": 0.1}}),
           "parameters": (HIT, {**HIT_LEARNING, "controller": {"type": "assist-as-needed"},
                                "learning.action": {"kind": "parameters", "parameters": {"k_max": [200, 3000]}}})}


@pytest.mark.parametrize("path, overrides", ACTIONS.values(), ids=ACTIONS)
def test_reset_frees_the_last_episode_without_the_collector(path, overrides, monkeypatch):
    """A reset that builds the run again (random targets, a robot's backend: where the start can't be restored) frees
    the last episode by reference counting alone — its MuJoCo scene is ~100 MB with a musculoskeletal arm — so it needs
    no full collection (~50 ms): a reference cycle anywhere in the run, or in the start's snapshot, would hold it."""
    env = ScenarioEnv(path, {**overrides, "duration": 0.2})
    env.reset(seed=1)
    env.step(np.zeros(env.action_space.shape, np.float32))  # (the loop leaves the run in the oldest generation)
    a = env._a  # every part of the run but those all runs share (the plugin registry, the extensions)
    parts = {"session": env._session, "scene": a.backend.model, **a.sensors,
             **{k: v for k, v in vars(a).items() if k not in ("registry", "extensions") and _weak(v)}}
    old = {name: weakref.ref(part) for name, part in parts.items()}
    del a, parts
    full = []
    monkeypatch.setattr(gc, "collect", lambda generation=2: full.append(generation) or 0)  # (collects nothing)
    gc.disable()
    try:
        assert env._start is not None  # (the start's snapshot, held until the run is dropped)
        env.close_run()
        env._open(2)
        alive = [name for name, ref in old.items() if ref() is not None]
    finally:
        gc.enable()
    assert alive == [] and full == []
    env.close()


def _weak(x) -> bool:
    try:
        weakref.ref(x)
    except TypeError:  # (None, dicts, lists)
        return False
    return True


def test_a_dangerous_action_ends_in_a_safety_stop_not_a_crash():
    env = ScenarioEnv(HIT, {**HIT_LEARNING, "learning.action": {"kind": "torque", "scale": 1.0}})
    env.reset(seed=0)
    full = np.ones(env.action_space.shape, np.float32)  # every joint's whole effort, one way
    for _ in range(100):
        _, _, terminated, truncated, info = env.step(full)
        if terminated or truncated:
            break
    assert terminated and not truncated
    assert info["safety"]["rule"] in {"velocity", "position", "torque"} and info["safety"]["category"] == 2  # held
    assert info["reward_terms"]["safety_stop"] == -10.0  # stopping early is no way out of the costs
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(full)
    env.close()


def test_two_environments_step_in_an_async_vector_env():
    envs = gymnasium.vector.AsyncVectorEnv(
        [lambda: gymnasium.make("rehabkit.gym:rehabkit/Scenario-v0", scenario=str(HIT), overrides=HIT_LEARNING)] * 2)
    obs, _ = envs.reset(seed=[1, 2])
    for _ in range(5):
        obs, rewards, terminated, truncated, _ = envs.step(np.zeros((2, 6), np.float32))
    assert obs.shape == (2, envs.single_observation_space.shape[0]) and np.all(np.isfinite(rewards))
    assert not terminated.any() and not truncated.any()
    envs.close()


def test_renders_the_scene():
    env = ScenarioEnv(HIT, HIT_LEARNING, render_mode="rgb_array", render_size=(120, 160))
    env.reset(seed=0)
    image = env.render()
    assert image.shape == (120, 160, 3) and image.dtype == np.uint8 and image.std() > 5
    env.close()


def test_learning_settings_are_checked_and_located():
    with pytest.raises(ScenarioError) as bad_rate:
        ScenarioEnv(HIT, {"learning": {"policy_hz": 300}})  # 1000 Hz control: not a whole number of steps
    assert [d.path for d in bad_rate.value.diagnostics] == ["learning.policy_hz"]
    with pytest.raises(ScenarioError) as none:
        ScenarioEnv(HIT)
    assert [(Path(d.mark.file).name, d.path) for d in none.value.diagnostics] == [(HIT.name, "")]  # (the whole file)
    with pytest.raises(ScenarioError) as pixels:  # (pixels needs layout: dict)
        ScenarioEnv(HIT, {"learning": {"observation": {"terms": ["joint_state", "pixels"]}}})
    assert [d.path for d in pixels.value.diagnostics] == ["learning"]


def test_a_policy_runs_as_a_controller_exactly_as_in_its_environment(tmp_path):
    """A policy acting in the environment and the same file run by the `policy` controller in the scenario give the
    same motion, sample for sample: what is learned is what runs (in simulation, and over the link)."""
    learning = {"learning": {"policy_hz": 50, "action": {"kind": "residual", "scale": 0.05},
                             "observation": {"terms": ["joint_state", "tracking_error", "phase"]}}}
    env = ScenarioEnv(HIT, {**learning, "duration": 2.0})
    n_obs, n_act = env.observation_space.shape[0], env.action_space.shape[0]
    rng = np.random.default_rng(4)
    policy = Policy.zeros([n_obs, 8, n_act], std=np.full(n_obs, 2.0), meta=env.policy_meta())
    policy = policy.with_flat(rng.normal(0, 0.5, len(policy.flat())))
    path = policy.save(tmp_path / "hit.npz")
    obs, _ = env.reset(seed=0)
    actions = []
    while True:
        actions.append(policy(obs))
        obs, _, terminated, truncated, _ = env.step(actions[-1])
        if terminated or truncated:
            break
    learned_q = env._session.trace.q.copy()
    assert np.abs(np.array(actions)).max() > 0.3  # the policy did act
    env.close()
    run = run_scenario(HIT, {"duration": 2.0, "controller": {"type": "policy", "file": str(path)}})
    assert run.metrics["safety_events"] == 0
    assert np.array_equal(run.trace.q, learned_q)
    # over the robot link (the bridge on the host's clock), the same controller, the same motion
    link = run_scenario(HIT, {"duration": 2.0, "controller": {"type": "policy", "file": str(path)},
                              "backend": {"type": "hardware", "clock": "lockstep"}})
    assert link.metrics["safety_events"] == 0 and link.metrics["link_ticks"] == len(learned_q)
    assert np.abs(link.trace.q - learned_q).max() < 1e-9


def test_a_policy_that_needs_what_a_controller_cannot_see_is_refused(tmp_path):
    env = ScenarioEnv(HIT, {"learning": {"observation": {"terms": ["joint_state", "goal"]}}, "duration": 0.5})
    policy = Policy.zeros([env.observation_space.shape[0], 6], meta=env.policy_meta()).save(tmp_path / "p.npz")
    with pytest.raises(ScenarioError) as refused:
        run_scenario(HIT, {"controller": {"type": "policy", "file": str(policy)}})
    assert ([d.path for d in refused.value.diagnostics], refused.value.setting) == (["controller"], ("file",))


def test_a_policy_can_tune_the_controllers_own_settings(tmp_path):
    tuning = {"controller": {"type": "assist-as-needed"}, "duration": 1.0,
              "learning": {"policy_hz": 50, "action": {"kind": "parameters", "parameters": {"k_max": [200, 3000]}},
                           "observation": {"terms": ["joint_state", "phase"]}}}
    env = ScenarioEnv(HIT, tuning)
    env.reset(seed=0)
    assert env.action_space.shape == (1,)
    env.step(np.array([1.0], np.float32))
    assert env._a.controller.cfg.k_max == pytest.approx(3000)
    env.step(np.array([-1.0], np.float32))
    assert env._a.controller.cfg.k_max == pytest.approx(200)
    with pytest.raises(ScenarioError) as untuned:  # joint-pd tunes nothing: not k_max
        ScenarioEnv(HIT, {**tuning, "controller": {"type": "joint-pd", "kp": 100, "kd": 10}})
    assert [d.path for d in untuned.value.diagnostics] == ["learning.action.parameters"]
    policy = Policy.zeros([env.observation_space.shape[0], 1], meta=env.policy_meta()).save(tmp_path / "k.npz")
    env.close()
    run = run_scenario(HIT, {"duration": 1.0, "controller": {"type": "policy", "file": str(policy)}})
    assert run.metrics["aan_stiffness_max"] <= 1600 + 1e-6  # tanh(0) = 0: k_max half way, as the file says


def test_a_policy_can_see_a_world_camera():
    seeing = {"learning": {"policy_hz": 50, "observation": {"terms": ["joint_state", "pixels"], "layout": "dict",
                                                            "camera": "front", "width": 32, "height": 24}},
              "world": {"cameras": [{"name": "front", "position": [-1.5, 0, 1.3], "look_at": [-0.4, 0, 1.1]}]},
              "duration": 0.1}
    env = ScenarioEnv(HIT, seeing)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and obs["pixels"].shape == (24, 32, 3) and obs["pixels"].std() > 1
    env.close()
