"""Any scenario with a ``learning:`` section as a Gymnasium environment.

Each episode is the scenario's run, its seed the episode's (the targets, the sensors' and the patient's noise are the
episode's own, and the same seed gives the same episode bit for bit). The run is built once: a reset puts its session
back where it stood at the start (:mod:`rehabkit.core.run.snapshot`, MuJoCo's state among it) and re-seeds its random
generators in place — a few milliseconds, where building it again took a tenth of a second. Where the start depends
on the seed otherwise (random targets, a draw made while the run was built) or the backend is a robot's, the reset
builds the run afresh, as it always may; ``info["reset"]`` says which it did. The episode is then
advanced a policy period at a time through the same control loop a run uses — events, sensors, the scenario's
controller, the person, the safety layer, the backend. The action acts on the controller's torque (``residual``:
added to it; ``torque``: instead of it, over the robot's gravity compensation), scaled to the joints' effort limits,
and passes the safety layer like any command: a safety stop ends the episode (``terminated``, the event in
``info``), the scenario's duration truncates it. Rewards are the ``learning.reward`` terms, each reported in
``info["reward_terms"]``.
"""

from __future__ import annotations

import gc
import weakref
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from threadpoolctl import ThreadpoolController

from rehabkit.core.kinds.backend import NotRestorableError
from rehabkit.core.run.loop import run_loop
from rehabkit.core.run.runner import Runner
from rehabkit.core.run.session import RunSession
from rehabkit.core.run.snapshot import SessionSnapshot, restore, snapshot
from rehabkit.core.scenario.loader import LoadedScenario, load_scenario
from rehabkit.core.setup.errors import PluginSetupError
from rehabkit.gym.terms import Observer, RewardTerms


class ScenarioEnv(gym.Env):
    """A scenario file as an environment: ``ScenarioEnv("scenarios/x.yaml", overrides=["a.b=1"])`` or
    ``gymnasium.make("rehabkit/Scenario-v0", scenario=..., overrides=[...])``."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, scenario: str | Path, overrides: list[str] | dict[str, Any] = (), render_mode: str | None = None,
                 render_size: tuple[int, int] = (480, 640)):
        self.path, self.overrides = Path(scenario), overrides
        loaded = load_scenario(self.path, overrides)  # bad input: a located ScenarioError, before anything runs
        self._loaded = loaded
        self.spec_learning = _learning(loaded)
        sc = loaded.model
        self.every = _policy_every(loaded)
        self.render_mode, self.render_size = render_mode, render_size
        self._renderer = None
        self._session: RunSession | None = None
        self._acting = None
        self._start: SessionSnapshot | None = None  # the session at the start: what a reset puts back
        self._blas = ThreadpoolController()  # found once: looking for the libraries costs ~1.4 ms a policy step
        self._open(sc.seed)
        n = len(self._tuned[0]) if self._tuned else self._dof
        self.action_space = gym.spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_space = self.observer.space()

    # -- episodes --------------------------------------------------------------------------------------

    def _rewind(self, seed: int) -> bool:
        """Stand at the start again with this seed without building the run (the module docstring says when);
        whether it could."""
        if self._start is None:
            return False
        restore(self._session, self._start)  # (its generators as they were made: then re-seeded, each in place)
        self._a.context.seeds.reseed(seed)
        self._u[:] = 0.0
        self._ended = False
        return True

    def _open(self, seed: int) -> None:
        """Build the scenario afresh with this seed and stand at its start."""
        self.close_run()
        # the validated scenario with the episode's seed (a deep copy: a run's setup may adapt its sections)
        loaded = self._loaded
        session = Runner(replace(loaded, model=loaded.model.model_copy(update={"seed": seed}, deep=True))).start()
        a = session.setup
        self._session, self._a, self._sc, self._dof = session, a, a.sc, a.robot.model.dof
        self._ended = False
        limit = a.robot.model.limits.effort
        scale = self.spec_learning.action.scale
        self._scale = limit * (np.asarray(scale, float) if isinstance(scale, list) else scale)
        if len(np.atleast_1d(self._scale)) not in (1, self._dof):
            raise ValueError(f"learning.action.scale: {len(scale)} values for a robot of {self._dof} joints")
        self._u = u = np.zeros(self._dof)
        controller = a.controller
        inner = controller.compute
        action = self.spec_learning.action
        self._tuned = self._acting = None
        if action.kind == "parameters":  # the controller's own settings, each from its range
            names = list(action.parameters)
            try:
                controller.tune({})
                controller.tune({n: action.parameters[n][0] for n in names})
            except ValueError as exc:
                raise PluginSetupError(a.loaded.source, ("learning", "action", "parameters"),
                                       f"learning.action.parameters: {exc}") from None
            lo, hi = (np.array([action.parameters[n][i] for n in names]) for i in (0, 1))
            self._tuned = (names, lo, hi)
        elif action.kind == "residual":
            self._acting = lambda *args: inner(*args) + u  # noqa: E731
        else:
            gravity = a.robot.gravity_torque
            self._acting = lambda t, q, *rest: gravity(q) + u  # noqa: E731
        self.observer = Observer(self.spec_learning.observation, session)
        self.rewards = RewardTerms(self.spec_learning.reward, session, self.every)
        self._start = self._snapshot_start(session)

    def _snapshot_start(self, session: RunSession) -> SessionSnapshot | None:
        """The start to put back at each reset, where the start is the same on any seed but for the generators the
        run made (none drawn from yet) and the backend can put its state back."""
        a = session.setup
        if any(t.random is not None for t in a.sc.task.targets) or not a.context.seeds.untouched():
            return None
        try:
            return snapshot(session)
        except NotRestorableError:
            return None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        episode_seed = seed if seed is not None else int(self.np_random.integers(2**31 - 1))
        how = "restored"
        if not self._rewind(episode_seed):
            self._open(episode_seed)
            how = "built"
        return self.observer.observe(0), {"seed": episode_seed, "t": 0.0, "reset": how}

    def step(self, action):
        a, st = self._a, self._session.loop
        if self._ended:
            raise RuntimeError("the episode has ended: call reset()")
        action = np.clip(np.asarray(action, float), -1.0, 1.0)
        if self._tuned is not None:
            names, lo, hi = self._tuned
            a.controller.tune(dict(zip(names, lo + (action + 1.0) * (hi - lo) / 2)))
        else:
            self._u[:] = self._scale * action
        k0 = st.k
        controller, acting = a.controller, self._acting
        if acting is not None:  # on the controller for the period alone (the loop reads .compute as it starts):
            own = vars(controller).get("compute")  # kept there, it would hold the controller (`inner`) in a cycle
            controller.compute = acting
        try:
            with self._blas.limit(limits=1, user_api="blas"):  # (as in a run: BLAS threads only spin here)
                run_loop(self._session, k_to=k0 + self.every)
        finally:
            if acting is not None:
                if own is None:
                    del controller.compute
                else:
                    controller.compute = own
        terms = self.rewards.terms(k0, st.k)
        reward = float(sum(terms.values()))
        safety = self._session.safety
        terminated = safety.tripped_at is not None
        truncated = not terminated and (st.k >= a.schedule.steps or st.stopped)
        self._ended = terminated or truncated
        info: dict[str, Any] = {"t": st.k * a.schedule.control_dt, "reward_terms": terms}
        if terminated:
            terms["safety_stop"] = -self.spec_learning.stop_penalty
            reward -= self.spec_learning.stop_penalty
            trip = next(e for e in reversed(safety.events) if e.t == safety.tripped_at)
            # the stop's category as a field (0 off, 1 ramp then off, 2 ramp then held; None: a reaction, no stop)
            info["safety"] = {"rule": trip.rule, "joint": trip.joint, "t": trip.t, "message": trip.message,
                              "category": trip.data.get("category")}
        return self.observer.observe(st.k), reward, terminated, truncated, info

    def policy_meta(self) -> dict:
        """What a policy trained here must carry for the ``policy`` controller to run it (rehabkit.models.policy)."""
        sc, spec = self._sc, self.spec_learning
        return {"terms": list(spec.observation.terms), "dof": self._dof, "policy_hz": spec.policy_hz,
                "duration_s": sc.duration, "scenario": self.path.name,
                "action": {"kind": spec.action.kind, "scale": spec.action.scale,
                           "parameters": {k: list(v) for k, v in spec.action.parameters.items()}},
                "base": sc.controller.model_dump(mode="json") if spec.action.kind != "torque" else None}

    # -- the view --------------------------------------------------------------------------------------

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import mujoco

        from rehabkit.sim.scene_view import SceneView

        backend = self._a.backend
        if not isinstance(backend, SceneView):  # (a simulation's scene: a robot's backend has none to render here)
            raise RuntimeError(f"backend '{self._a.sc.backend.type}' has no scene to render")
        model, data = backend.model, backend.data
        if self._renderer is None or self._renderer_model is not model:
            self._renderer = mujoco.Renderer(model, *self.render_size)
            self._renderer_model = model
        camera = self.spec_learning.observation.camera
        if camera is None:
            camera = mujoco.MjvCamera()
            camera.lookat[:] = self._a.robot.model.base_pose[:3, 3]
            camera.distance, camera.azimuth, camera.elevation = 1.8, 150.0, -20.0
        self._renderer.update_scene(data, camera)
        return self._renderer.render()

    def close_run(self) -> None:
        """End the episode's run: its backend closed, and every reference to it dropped so that it — its MuJoCo
        scene, ~100 MB with a musculoskeletal arm — is freed here, by reference counting."""
        if self._renderer is not None:  # (it holds the episode's model; the next episode's needs its own)
            self._renderer.close()
            self._renderer = self._renderer_model = None
        self._start = None  # (it holds the run's parts)
        if self._session is None:
            return
        a = self._a
        a.backend.close()
        held = [weakref.ref(x) for x in (self._session, a, a.backend)]
        self._session = self._a = self.observer = self.rewards = self._acting = a = None
        if any(ref() is not None for ref in held):
            # a plugin's reference cycle holds it: the collector, seeing only its small Python side, would not run
            # for it (a learner's worker grew to 10 GB), so a full collection frees it now
            gc.collect()

    def close(self) -> None:
        self.close_run()


def _learning(loaded: LoadedScenario):
    if loaded.model.learning is None:
        raise PluginSetupError(loaded.source, (), f"{loaded.path.name} has no learning: section (the policy's "
                               "action, observation, reward and rate)", fix="add one to use it as an environment")
    return loaded.model.learning


def _policy_every(loaded: LoadedScenario) -> int:
    """Control steps a policy step spans: the control rate over the policy rate, a whole number."""
    sc = loaded.model
    every = sc.rates.control_hz / sc.learning.policy_hz
    if abs(every - round(every)) > 1e-9 or round(every) < 1:
        raise PluginSetupError(loaded.source, ("learning", "policy_hz"),
                               f"learning.policy_hz: {sc.learning.policy_hz:g} Hz does not divide the control rate "
                               f"{sc.rates.control_hz:g} Hz; take one that does (e.g. {sc.rates.control_hz / 20:g})")
    return round(every)

