"""Framework overhead: the full runner against a bare MuJoCo loop, measured side by side.

Both run the HIT round-trip on the same compiled model with the same reference
trajectory and the same control law (joint PD + Pinocchio RNEA feedforward + the joints' declared damping) at
1 kHz. The runner adds everything a scenario gets: event handling, sensors,
the safety layer, the trace, contact checks and Rerun logging at 100 Hz (file
finished and renamed). Repeats alternate the two so drift affects both alike;
the best of each is compared.

End to end, as a user waits: the README's main job (``rehabkit run
scenarios/hit_roundtrip.yaml --out DIR``, process start to exit) against a
process that only imports the engines it needs (mujoco, pinocchio, rerun,
pydantic's BaseModel, yaml, numpy), alternated, median of the repeats; both with
their bytecode compiled, as installed packages have it. (A bare ``import
pydantic`` loads none of pydantic 2's validation engine; that floor is printed
too.)

    python benchmarks/bench_runner.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import compileall
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import yaml

from rehabkit.core.run.runner import Runner
from rehabkit.core.scenario.loader import load_scenario

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "hit_roundtrip.yaml"


def _law(runner: Runner) -> tuple:
    """What the hand-written loops need of a built run: MuJoCo's model and data, the joint-pd law's gains, Pinocchio's
    model and data, the joints' declared damping, the joints' qpos and qvel spans."""
    backend, model = runner.backend, runner.robot.model
    cfg = runner.sc.controller
    pm = model.pin_model
    assert not np.any(model.dissipation.friction)  # (else the law would compensate it as well)
    # (HIT's damping: 0.5-0.1 N·m·s/rad, in MuJoCo's model too)
    return (backend.model, backend.data, np.asarray(cfg.kp, float), np.asarray(cfg.kd, float), pm, pm.createData(),
            model.dissipation.damping, backend._q, backend._v)


def bare_loop(runner: Runner, ref: tuple[np.ndarray, np.ndarray, np.ndarray]) -> float:
    """Seconds for the plain loop: read state, PD + RNEA (+ the joints' declared damping, as the controller
    compensates it), write torque, mj_step."""
    m, d, kp, kd, pm, pdata, damping, qs, vs = _law(runner)
    q_ref, qd_ref, qdd_ref = ref
    runner.backend.reset(q_ref[0])
    t0 = time.perf_counter()
    for k in range(len(q_ref)):
        q, qd = d.qpos[qs], d.qvel[vs]
        tau = kp * (q_ref[k] - q) + kd * (qd_ref[k] - qd) + pin.rnea(pm, pdata, q, qd_ref[k], qdd_ref[k])
        tau += damping * qd_ref[k]
        d.qfrc_applied[vs] = tau
        mujoco.mj_step(m, d)
    elapsed = time.perf_counter() - t0
    err = np.degrees(np.abs(q_ref[-1] - d.qpos[qs]).max())
    assert err < 0.5, f"bare loop did not track (final error {err:.3f} deg)"
    return elapsed


def floor_loop(scenario: Path) -> float:
    """Seconds for the bare loop plus what no run may leave out: each step's ``[q, qd, tau]`` row in a trace and the
    safety layer's check of it, its torque the one sent (the runner's own layer, set up as a run sets it up)."""
    runner = Runner(load_scenario(scenario))
    session = runner.start()
    m, d, kp, kd, pm, pdata, damping, qs, vs = _law(runner)
    n = runner.robot.model.dof
    q_ref, qd_ref, qdd_ref = session.ref.views()
    packed = np.zeros_like(session.packed)
    tq, tqd, ttau = packed[:, :n], packed[:, n : 2 * n], packed[:, 2 * n :]
    check, dt = session.safety.check_row, session.setup.schedule.control_dt
    runner.backend.reset(q_ref[0])
    t0 = time.perf_counter()
    for k in range(len(q_ref)):
        q, qd = d.qpos[qs], d.qvel[vs]
        tq[k], tqd[k] = q, qd
        tau = kp * (q_ref[k] - q) + kd * (qd_ref[k] - qd) + pin.rnea(pm, pdata, q, qd_ref[k], qdd_ref[k])
        tau += damping * qd_ref[k]
        ttau[k] = tau
        d.qfrc_applied[vs] = check(k * dt, packed[k])
        mujoco.mj_step(m, d)
    elapsed = time.perf_counter() - t0
    assert session.safety.tripped_at is None
    return elapsed


def recording_floor(trace) -> float:
    """Seconds to record a finished run's joint series as the runner's recording holds them (each joint's measured
    and reference position, the speeds, efforts and errors: 15 entities of one row a control step) in an ``.rrd``
    file, and close it: the least a recorded run adds after its loop. The 15 entities go in one Arrow record batch
    (:class:`~rehabkit.core.log.entity_columns.EntityColumns`, as the runner sends them; a ``send_columns`` call an
    entity costs ~0.2 ms more each)."""
    import rerun as rr

    from rehabkit.core.log.entity_columns import EntityColumns

    t, q, qd, tau = trace.t, np.degrees(trace.q), np.degrees(trace.qd), trace.tau
    ref = np.degrees(trace.q_ref)
    series = [(f"joints/{j}/{name}", values[:, j]) for j in range(q.shape[1])
              for name, values in (("measured", q), ("reference", ref))]
    series += [("joints/speed", qd), ("joints/effort", tau), ("joints/error", ref - q)]
    with tempfile.TemporaryDirectory() as out:
        rec = rr.RecordingStream("rehabkit-floor")
        rec.save(Path(out) / "floor.rrd")
        t0 = time.perf_counter()
        columns = EntityColumns()
        for path, values in series:
            columns.scalars(path, t, values)
        for batch in columns.take():
            rec.send_record_batch(batch)
        rec.flush()
        rec.disconnect()
        return time.perf_counter() - t0


def full_run(scenario: Path) -> tuple[float, float, Runner]:
    """(loop seconds, loop + finishing the log and summary, runner) for one complete run."""
    with tempfile.TemporaryDirectory() as out:
        runner = Runner(load_scenario(scenario), out_dir=Path(out))
        t0 = time.perf_counter()
        result = runner.run()
        total = time.perf_counter() - t0 - result.metrics["setup_time_s"]
        assert result.passed, result.failures
        assert (Path(out) / "run.rrd").stat().st_size > 0
        return result.metrics["wall_time_s"], total, runner


# pydantic 2's top-level module is lazy: `import pydantic` loads none of its validation machinery (~5 ms), while
# anything that validates (BaseModel) loads it all (~50-70 ms here); the floor imports each engine as a user of it
ENGINES = "import mujoco, pinocchio, rerun, yaml, numpy; from pydantic import BaseModel"
ENGINES_LAZY = "import mujoco, pinocchio, rerun, pydantic, yaml, numpy"  # the floor as first written, for comparison


def end_to_end(repeats: int) -> tuple[float, float, float]:
    """Median wall seconds of (the main job as a process, a process importing only the engines, the same with
    pydantic's lazy top-level module alone)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    # the engines' bytecode was compiled when pip installed them, and an installed rehabkit's is too; an editable
    # checkout's is compiled here, so that neither side pays for compiling (PYTHONDONTWRITEBYTECODE may be set)
    for package in ("rehabkit", "plugins"):
        compileall.compile_dir(str(SCENARIO.parents[1] / package), quiet=1)
    job, floor, lazy = [], [], []
    with tempfile.TemporaryDirectory() as out:
        for _ in range(repeats):
            for cmd, times in (([sys.executable, "-m", "rehabkit.cli", "run", str(SCENARIO), "--out", out], job),
                               ([sys.executable, "-c", ENGINES], floor), ([sys.executable, "-c", ENGINES_LAZY], lazy)):
                t0 = time.perf_counter()
                subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
                times.append(time.perf_counter() - t0)
    return statistics.median(job), statistics.median(floor), statistics.median(lazy)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    # --set merges mappings, so the sensor-free variant is the scenario file without its sensors section
    data = yaml.safe_load(SCENARIO.read_text())
    data.pop("sensors", None)
    bare_file = Path(tempfile.mkdtemp()) / "hit_roundtrip_no_sensors.yaml"
    bare_file.write_text(yaml.safe_dump(data))
    # and with its ROS 2 bag, streamed as the run goes (every control step's joint states and reference, /tf at the
    # log rate, the encoder's readings; a chunk flushed to the file at least every second)
    bag_file = bare_file.with_name("hit_roundtrip_bag.yaml")
    bag_file.write_text(yaml.safe_dump({**yaml.safe_load(SCENARIO.read_text()), "ros": {"bag": True}}))
    variants = {"runner (no sensors)": bare_file, "runner (scenario as written, 500 Hz encoder)": SCENARIO,
                "runner (as written + ROS 2 bag, streamed)": bag_file}
    best: dict[str, list[float]] = {"bare MuJoCo loop": [], "floor: bare + trace row + safety check": []} | {
        k: [] for k in variants}
    floor_finish: list[float] = []
    best_total: dict[str, list[float]] = {k: [] for k in variants}
    sim_time = None
    for _ in range(args.repeats):
        for name, scenario in variants.items():
            loop, total, runner = full_run(scenario)
            best[name].append(loop)
            best_total[name].append(total)
            sim_time = runner.sc.duration
        best["bare MuJoCo loop"].append(bare_loop(runner, runner.session.ref.views()))
        best["floor: bare + trace row + safety check"].append(floor_loop(bare_file))
        floor_finish.append(recording_floor(runner.session.trace.trimmed(runner.session.loop.k)))
    bare = min(best["bare MuJoCo loop"])
    steps = int(round(sim_time * 1000))
    print(f"HIT round-trip, {sim_time} s simulated, {steps} steps at 1 kHz; best of {args.repeats}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, MuJoCo {mujoco.__version__}, Pinocchio {pin.__version__}")
    print(f"{'':46} {'loop s':>8} {'us/step':>8} {'x real time':>12} {'ratio':>7}")
    for name, times in best.items():
        t = min(times)
        print(f"{name:46} {t:8.3f} {t / steps * 1e6:8.1f} {sim_time / t:12.1f} {t / bare:7.2f}")
    for name, times in best_total.items():
        t = min(times)
        print(f"{name + ' incl. log/summary close':46} {t:8.3f} {t / steps * 1e6:8.1f} {sim_time / t:12.1f} "
              f"{t / bare:7.2f}")
    t = min(best["floor: bare + trace row + safety check"]) + min(floor_finish)
    print(f"{'floor incl. recording the joint series':46} {t:8.3f} {t / steps * 1e6:8.1f} {sim_time / t:12.1f} "
          f"{t / bare:7.2f}   (the recording alone: {min(floor_finish) * 1e3:.1f} ms)")
    job, floor, lazy = end_to_end(max(3, args.repeats))
    print(f"end to end (process start to exit, median of {max(3, args.repeats)}): `rehabkit run "
          f"scenarios/hit_roundtrip.yaml` {job:.2f} s, importing the engines alone {floor:.2f} s, ratio "
          f"{job / floor:.2f} (with pydantic's lazy `import pydantic` as its import: {lazy:.2f} s, ratio "
          f"{job / lazy:.2f})")


if __name__ == "__main__":
    main()
