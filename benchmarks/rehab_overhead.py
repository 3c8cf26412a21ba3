"""What the rehab layer costs in the control loop, measured side by side.

The HIT round trip (8,500 steps at 1 kHz, no log) run plainly and with each piece of the rehab
layer the loop runs every step: the keep-in box (forward kinematics of the hand), a simulated
patient (its torques applied to the joints), the patient with an interaction-force limit (the
hand force from the Jacobian, least squares), the assist-as-needed controller in place of
the joint PD, and a force-torque sensor read (tared, filtered) and checked every step. Repeats
alternate the variants so drift affects all alike; the best loop time of each is compared with the
plain run's.

    python benchmarks/rehab_overhead.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import warnings
from pathlib import Path

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "hit_roundtrip.yaml"
PATIENT = {"id": "B1", "side": "right",
           "model": {"type": "simulated-arm", "stiffness_nm_rad": [1, 1, 0.5, 0.5, 0.05, 0.05],
                     "damping_nms_rad": [0.3, 0.3, 0.1, 0.1, 0.01, 0.01],
                     "spasticity": {"gain_nms_rad": [0, 0, 0.5, 0.5, 0, 0]},
                     "voluntary": {"strength_nm": [4, 4, 2, 2, 0.1, 0.1], "stiffness": 20, "damping": 2}}}
VARIANTS = {
    "plain": {},
    "keep-in box": {"safety": {"keep_in": {"min": [-2, -2, -2], "max": [2, 2, 2]}}},
    "simulated patient": {"patient": PATIENT},
    "patient + force limit": {"patient": {**PATIENT, "comfort": {"max_interaction_force_n": 1e6}}},
    "assist-as-needed": {"controller.type": "assist-as-needed"},
    "force-torque + force limit": {"sensors": {"ft": {"type": "force-torque"}}, "safety": {"interaction_force_n": 1e6}},
}


def loop_seconds(overrides: dict) -> float:
    """The run's control-loop wall time (setup and the summary excluded)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the controller swap drops the PD gains, with a warning
        loaded = load_scenario(SCENARIO, {"logging.rrd": False, **overrides})
    summary = Runner(loaded).run().summary
    if summary["metrics"]["sim_time_s"] < 8.5 - 1e-6:
        raise SystemExit(f"{overrides}: the run stopped early: {summary['safety']['events']}")
    return summary["metrics"]["wall_time_s"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    best = {name: float("inf") for name in VARIANTS}
    for _ in range(args.repeats):
        for name, overrides in VARIANTS.items():
            best[name] = min(best[name], loop_seconds(overrides))
    steps = 8500
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, best of {args.repeats}")
    print(f"{'variant':<24}{'loop [s]':>10}{'per step [µs]':>16}{'vs plain':>10}")
    for name, t in best.items():
        print(f"{name:<24}{t:>10.3f}{t / steps * 1e6:>16.1f}{t / best['plain']:>10.2f}")


if __name__ == "__main__":
    main()
