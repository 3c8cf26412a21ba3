"""What a learning environment costs over running the scenario itself, measured side by side.

For each scenario: the runner's loop over the whole session (as `rehabkit run` does it, no output files), against
an episode of the same session in ``rehabkit.gym`` with a zero action at the learning section's policy rate (its
steps timed, not its reset), and the reset alone. Repeats alternate the two; the best of each is kept.

    python benchmarks/gym_env.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.gym.env import ScenarioEnv

ROOT = Path(__file__).resolve().parents[1]
CASES = {"hit_roundtrip.yaml": {"learning": {"policy_hz": 50}}, "hit_myoarm.yaml": {}, "lexos_myoarm.yaml": {}}


def run_loop_s(path: Path, overrides: dict) -> float:
    result = Runner(load_scenario(path, overrides)).run()
    return result.metrics["wall_time_s"]


def episode_s(env: ScenarioEnv) -> tuple[float, float, int]:
    t = time.perf_counter()
    env.reset(seed=0)
    reset = time.perf_counter() - t
    zero = np.zeros(env.action_space.shape, np.float32)
    steps, t = 0, time.perf_counter()
    while True:
        _, _, terminated, truncated, _ = env.step(zero)
        steps += 1
        if terminated or truncated:
            return time.perf_counter() - t, reset, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print(f"{'scenario':22s} {'run loop s':>10s} {'episode s':>10s} {'ratio':>7s} {'policy steps':>13s} "
          f"{'us/step':>8s} {'reset s':>8s}")
    for name, overrides in CASES.items():
        path = ROOT / "scenarios" / name
        env = ScenarioEnv(path, overrides)
        loops, episodes, resets, steps = [], [], [], 0
        for _ in range(args.repeats):
            loops.append(run_loop_s(path, overrides))
            wall, reset, steps = episode_s(env)
            episodes.append(wall)
            resets.append(reset)
        env.close()
        loop, episode = min(loops), min(episodes)
        print(f"{name:22s} {loop:10.3f} {episode:10.3f} {episode / loop:7.3f} {steps:13d} "
              f"{1e6 * episode / steps:8.0f} {min(resets):8.3f}")


if __name__ == "__main__":
    main()
