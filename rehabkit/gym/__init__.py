"""Scenarios as Gymnasium environments (:class:`~rehabkit.gym.env.ScenarioEnv`).

Importing this module registers ``rehabkit/Scenario-v0`` with Gymnasium (its entry point: the environment's class),
so ``gymnasium.make("rehabkit/Scenario-v0", scenario="scenarios/x.yaml", overrides=[...])`` builds one; without the
import, ``gymnasium.make("rehabkit.gym:rehabkit/Scenario-v0", ...)`` imports it first.
"""

from __future__ import annotations

import gymnasium

ENV_ID = "rehabkit/Scenario-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="rehabkit.gym.env:ScenarioEnv", disable_env_checker=True)


def make_env(scenario, overrides=(), render_mode=None):
    """The environment of a scenario file (the Python constructor; see :class:`~rehabkit.gym.env.ScenarioEnv`)."""
    from rehabkit.gym.env import ScenarioEnv

    return ScenarioEnv(scenario, overrides, render_mode=render_mode)


__all__ = ["ENV_ID", "make_env"]
