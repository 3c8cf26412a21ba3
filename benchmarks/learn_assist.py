"""Learn an assistive controller for the L-Exos reaching task with the musculoskeletal patient, on Ray.

A linear (or small MLP) policy on ``scenarios/lexos_myoarm.yaml``'s learning environment (a residual torque on the
joint PD, 50 Hz, seeing what a controller sees) is searched by CMA-ES (the ``cma`` package) with each generation's
rollouts spread over Ray actors, one environment each, every candidate scored on the same episode seeds. The best
policy is saved as a file the ``policy`` controller runs; the training curve is drawn; the policy is then compared
with the joint PD and assist-as-needed on the same sessions (seeds), outcome measures side by side; and the same
rollouts are timed serially and on Ray for the speed-up.

    python benchmarks/learn_assist.py [--generations 16] [--popsize 8] [--sigma 0.05] [--episode-s 8] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "lexos_myoarm.yaml"
MEASURES = ("reaches_completed", "sparc", "path_length_ratio", "time_to_target_s", "assistance_ratio",
            "peak_cuff_force_n", "muscle_effort", "tracking_rms_deg", "safety_events")


def rollout(env, policy, seed: int) -> float:
    """One episode's return."""
    obs, _ = env.reset(seed=seed)
    total = 0.0
    while True:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        total += reward
        if terminated or truncated:
            return total


class Worker:
    """An environment in a process of its own (a Ray actor), scoring candidates."""

    def __init__(self, overrides: dict):
        os.environ.setdefault("MUJOCO_GL", "egl")
        from rehabkit.gym.env import ScenarioEnv

        self.env = ScenarioEnv(SCENARIO, overrides)

    def score(self, policy, seeds: list[int]) -> float:
        return float(np.mean([rollout(self.env, policy, s) for s in seeds]))


def train(args) -> tuple:
    import cma
    import ray

    from rehabkit.gym.env import ScenarioEnv
    from rehabkit.models.policy import Policy

    overrides = {"duration": args.episode_s}
    env = ScenarioEnv(SCENARIO, overrides)
    n_obs, n_act = env.observation_space.shape[0], env.action_space.shape[0]
    # inputs normalised by what the PD alone sees on the training seeds
    seen = []
    for s in args.seeds:
        obs, _ = env.reset(seed=s)
        done = False
        while not done:
            seen.append(obs)
            obs, _, terminated, truncated, _ = env.step(np.zeros(n_act))
            done = terminated or truncated
    seen = np.array(seen)
    sizes = [n_obs, *args.hidden, n_act]
    base = Policy.zeros(sizes, seen.mean(0), seen.std(0) + 1e-3, env.policy_meta())
    env.close()
    ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
    actor = ray.remote(Worker)
    workers = [actor.remote(overrides) for _ in range(args.workers)]
    es = cma.CMAEvolutionStrategy(np.zeros(len(base.flat())), args.sigma,
                                  {"popsize": args.popsize, "seed": 1, "verbose": -9})
    curve, best, best_score = [], base, -np.inf
    t0 = time.perf_counter()
    for gen in range(args.generations):
        candidates = es.ask()
        jobs = [workers[i % len(workers)].score.remote(base.with_flat(x), args.seeds) for i, x in enumerate(candidates)]
        scores = ray.get(jobs)
        es.tell(candidates, [-s for s in scores])
        i = int(np.argmax(scores))
        if scores[i] > best_score:
            best, best_score = base.with_flat(candidates[i]), scores[i]
        curve.append((gen, float(np.mean(scores)), float(np.max(scores)), time.perf_counter() - t0))
        print(f"generation {gen:3d}: mean return {np.mean(scores):9.4f}, best {np.max(scores):9.4f}, "
              f"{time.perf_counter() - t0:6.1f} s", flush=True)
    train_s = time.perf_counter() - t0
    zero = ray.get(workers[0].score.remote(base, args.seeds))
    # the same rollouts (one generation) on Ray and serially, for the speed-up
    probe = [base.with_flat(x) for x in es.ask()]
    t = time.perf_counter()
    ray.get([workers[i % len(workers)].score.remote(p, args.seeds) for i, p in enumerate(probe)])
    on_ray = time.perf_counter() - t
    local = Worker(overrides)
    t = time.perf_counter()
    for p in probe:
        local.score(p, args.seeds)
    serial = time.perf_counter() - t
    ray.shutdown()
    return best, best_score, zero, curve, train_s, on_ray, serial


def compare(policy_file: Path, seeds: list[int], episode_s: float) -> dict[str, dict[str, float]]:
    from rehabkit.api import run_scenario

    controllers = {"joint-pd": {}, "assist-as-needed": {"controller": {"type": "assist-as-needed"}},
                   "learned policy": {"controller": {"type": "policy", "file": str(policy_file)}}}
    table = {}
    for name, override in controllers.items():
        rows = [run_scenario(SCENARIO, {**override, "duration": episode_s, "seed": s}).metrics for s in seeds]
        table[name] = {m: (float(np.mean([r[m] for r in rows])), float(np.std([r[m] for r in rows]))) for m in MEASURES}
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generations", type=int, default=16)
    parser.add_argument("--popsize", type=int, default=8)
    parser.add_argument("--sigma", type=float, default=0.05)  # (0.3: no candidate beat the PD in 20 generations)
    parser.add_argument("--hidden", type=int, nargs="*", default=[])
    parser.add_argument("--episode-s", type=float, default=8.0)  # (6 s ends the ramp-out mid-reach)
    parser.add_argument("--seeds", type=int, nargs="*", default=[0, 1])
    parser.add_argument("--eval-seeds", type=int, default=5)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "learn_assist")
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
          f"{args.workers} Ray workers")
    best, best_score, zero, curve, train_s, on_ray, serial = train(args)
    args.out.mkdir(parents=True, exist_ok=True)
    path = best.save(args.out / "lexos_myoarm_policy.npz")
    print(f"\ntrained in {train_s:.1f} s ({args.generations} generations × {args.popsize} candidates × "
          f"{len(args.seeds)} episodes of {args.episode_s:g} s); best return {best_score:.4f} (zero residual: "
          f"{zero:.4f}); policy: {path}")
    print(f"one generation's rollouts: {serial:.1f} s serially, {on_ray:.1f} s on Ray ({args.workers} workers): "
          f"speed-up {serial / on_ray:.2f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = np.array(curve)
    plt.figure(figsize=(6, 3.5))
    plt.plot(c[:, 0], c[:, 1], label="generation mean")
    plt.plot(c[:, 0], c[:, 2], label="generation best")
    plt.axhline(zero, color="grey", linestyle="--", label="zero residual (the PD alone)")
    plt.xlabel("generation")
    plt.ylabel("return")
    plt.title("CMA-ES on lexos_myoarm (Ray)")
    plt.legend()
    plt.tight_layout()
    plt.savefig(args.out / "training_curve.png", dpi=120)
    print(f"training curve: {args.out / 'training_curve.png'}")
    seeds = list(range(100, 100 + args.eval_seeds))  # sessions the training never saw
    table = compare(path, seeds, args.episode_s)
    print(f"\nsame sessions (seeds {seeds[0]}..{seeds[-1]}), mean ± std:")
    print(f"{'measure':20s}" + "".join(f"{name:>24s}" for name in table))
    for m in MEASURES:
        print(f"{m:20s}" + "".join(f"{table[n][m][0]:>15.4f} ± {table[n][m][1]:<6.3f}" for n in table))


if __name__ == "__main__":
    main()
