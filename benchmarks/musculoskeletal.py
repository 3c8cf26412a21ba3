"""The musculoskeletal patient: how fast, where the time goes, and the known answers it gives.

Speed: ``scenarios/lexos_myoarm.yaml`` (L-Exos + MyoArm, 12 s at 500 Hz on MuJoCo's 2 ms step) run by the runner,
its loop timed with the physics step, the static optimisation and the rest of the person's step each timed on
their own; beside it, in the same process, the same session with the spring-damper patient (``simulated-arm``)
and with no person; and ``rehabkit run ... --out DIR`` from process start to exit.

Known answers, on the elbow dynamometer (``examples/robots/elbow_dynamometer.yaml``, MyoElbow): isometric
flexion at full strength and at half the flexors' force; a Tardieu series with and without spasticity; the
tremor's spectral peak; fatigue under a sustained maximal effort and recovery.

    python benchmarks/musculoskeletal.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.musculo.dynamometer import MVC, RIGID, Dynamometer, isometric, tardieu

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "lexos_myoarm.yaml"
DYNO = ROOT / "examples" / "robots" / "elbow_dynamometer.yaml"
# the same session with another person, or none (only a strapped-in person has cuffs to expect on)
SPRING = f"extends: {SCENARIO}\npatient: {ROOT / 'scenarios' / 'patients' / 'p01.yaml'}\n" \
         "expect: {peak_cuff_force_n: null}\n"
NOBODY = f"extends: {SCENARIO}\npatient: null\nexpect: {{peak_cuff_force_n: null}}\n"


class Timer:
    """Wraps a bound method, summing the time spent in it."""

    def __init__(self, owner, name: str):
        self.total, self.calls, inner = 0.0, 0, getattr(owner, name)

        def timed(*args, **kwargs):
            t = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.total += time.perf_counter() - t
                self.calls += 1
        setattr(owner, name, timed)


def timed_run(scenario: Path, breakdown: bool) -> dict[str, float]:
    runner = Runner(load_scenario(scenario))
    build = runner.build

    def build_and_time():
        a = build()
        timers = {"physics": Timer(a.backend, "step")}
        if breakdown and a.patient is not None and hasattr(a.patient, "so"):
            timers["static optimisation"] = Timer(a.patient.so, "matrices")
            timers["static optimisation (QP)"] = Timer(a.patient.so, "solve")
            timers["person, all"] = Timer(a.patient, "torque")
        runner.timers = timers
        return a

    runner.build = build_and_time
    result = runner.run()
    m = result.metrics
    out = {"sim_s": m["sim_time_s"], "loop_s": m["wall_time_s"]}
    out.update({k: t.total for k, t in runner.timers.items()})
    return out


def speed(repeats: int) -> None:
    folder = Path(tempfile.mkdtemp())
    (folder / "spring.yaml").write_text(SPRING)
    (folder / "nobody.yaml").write_text(NOBODY)
    cases = {"MyoArm (musculoskeletal)": SCENARIO, "spring-damper (simulated-arm)": folder / "spring.yaml",
             "no person": folder / "nobody.yaml"}
    best: dict[str, dict[str, float]] = {}
    for _ in range(repeats):  # alternated, so the machine's drift touches all alike; best of each kept
        for name, scenario in cases.items():
            r = timed_run(scenario, name.startswith("MyoArm"))
            if name not in best or r["loop_s"] < best[name]["loop_s"]:
                best[name] = r
    print(f"\n## Speed: {SCENARIO.name}, {best['no person']['sim_s']:.1f} s simulated, best of {repeats}")
    print(f"{'case':32s} {'loop s':>8s} {'RTF':>6s} {'÷ no person':>12s}")
    for name, r in best.items():
        print(f"{name:32s} {r['loop_s']:8.2f} {r['sim_s'] / r['loop_s']:6.2f} "
              f"{r['loop_s'] / best['no person']['loop_s']:12.2f}")
    r = best["MyoArm (musculoskeletal)"]
    so = r["static optimisation"] + r["static optimisation (QP)"]
    parts = {"physics (mj_step: robot + 63 muscles + straps)": r["physics"],
             "static optimisation (moment arms, forces, QP)": so,
             "the person's other work (intent, reflex, straps, record)": r["person, all"] - so,
             "the rest (controller, safety, trace, log)": r["loop_s"] - r["physics"] - r["person, all"]}
    print("\nwhere the MyoArm loop's time goes:")
    for name, seconds in parts.items():
        print(f"  {name:58s} {seconds:6.2f} s  {100 * seconds / r['loop_s']:5.1f} %")
    with tempfile.TemporaryDirectory() as out:
        walls = []
        for _ in range(repeats):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "rehabkit.cli", "run", str(SCENARIO), "--out", out],
                           check=True, capture_output=True, env={**os.environ, "MUJOCO_GL": "egl"})
            walls.append(time.perf_counter() - t)
    wall = float(np.median(walls))
    print(f"\nend to end, `rehabkit run {SCENARIO.relative_to(ROOT)} --out DIR` (process start to exit, median): "
          f"{wall:.2f} s for {r['sim_s']:.0f} s simulated: real-time factor {r['sim_s'] / wall:.2f}")


def known_answers() -> None:
    print(f"\n## Known answers on {DYNO.relative_to(ROOT)} (MyoElbow)")
    full, rest = isometric(DYNO)
    half, rest_half = isometric(DYNO, {"patient.model.weakness": {"elbow_flexors": 0.5}})
    print(f"isometric flexion at 90°: full {-(full - rest):.2f} N·m, flexors at 0.5: {-(half - rest_half):.2f} N·m "
          f"(ratio {(half - rest_half) / (full - rest):.3f}); relaxed {rest:.3f} / {rest_half:.3f} N·m")
    spastic = {"patient.model.spasticity": {"gain": {"elbow_flexors": 0.1}, "threshold_l0_s": 0.3}}  # moderate
    print("Tardieu: stretch speed °/s | resistance N·m without / with spasticity | flexor excitation with")
    for speed_deg_s in (15, 30, 60, 90, 180, 270, 360):
        plain, _ = tardieu(DYNO, speed_deg_s)
        resist, excite = tardieu(DYNO, speed_deg_s, spastic)
        print(f"  {speed_deg_s:5.0f} | {plain:6.2f} / {resist:6.2f} | {excite:.3f}")
    for amplitude in (0.4, 0.0):
        bench = Dynamometer(DYNO, {"patient.model.tremor": {"amplitude_nm": {"elbow_flexion": amplitude},
                                                            "frequency_hz": 5.0}})
        speed = bench.run(4.0)["qd"][100:] * 0.25
        power = np.abs(np.fft.rfft(speed - speed.mean())) ** 2
        f = np.fft.rfftfreq(len(speed), bench.dt)
        band = (f > 4) & (f < 6)
        print(f"tremor {amplitude} N·m at 5 Hz: hand-speed spectrum peak at {f[1:][np.argmax(power[1:])]:.2f} Hz, "
              f"4-6 Hz power {power[band].sum():.3g}")
    bench = Dynamometer(DYNO, {**RIGID, "patient.model.fatigue": {"rate_per_s": 0.3, "recovery_per_s": 0.3}},
                        driven=True)
    hold = lambda t: (0.0, 0.0)  # noqa: E731
    sustained = bench.run(3.0, request=lambda t: MVC, lever=hold)["tau"]
    low = bench.person.run_metrics()["muscle_capacity_min"]
    bench.run(10.0, request=lambda t: np.zeros(1), lever=hold)
    back = bench.run(0.3, request=lambda t: MVC, lever=hold)["tau"][-25:].mean()
    print(f"fatigue (0.3/s): MVC {-sustained[25:50].mean():.1f} -> {-sustained[-25:].mean():.1f} N·m after 3 s "
          f"(capacity {low:.2f}); after 10 s of rest {-back:.1f} N·m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    speed(args.repeats)
    known_answers()


if __name__ == "__main__":
    main()
