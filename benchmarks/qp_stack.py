"""COMAN's stack of QPs: cycle time, and the cascade against one weighted QP of the same tasks.

The controller is configured exactly as in ``scenarios/coman_juggling.yaml`` and driven
kinematically (its own integrated configuration, no physics, so both solvers see the same
states) along the hand reference of three throws from the ``throw-lwlr`` planner. At every
cycle both solve the same levels and inequalities:

* the cascade (strict priorities: lower levels cannot degrade higher ones), as run in the
  scenario; the state advances with its solution;
* one QP with the levels stacked and weighted (soft priorities, weights 1000, 100, 10, 1).

Printed: per-level task residuals of both (priority respected: the cascade's residual of a
higher level is never worse), and the cycle times side by side (Jacobians + all solves for
the cascade; the same kinematics + one solve for the weighted QP): median, p99, worst and
their ratio. ``--cycles`` sets how many cycles (default: three throws, ~12,600).

    python benchmarks/qp_stack.py [--cycles N]
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from rehabkit.core.kinds.interfaces import Context, PlanRequest, Target
from rehabkit.core.plugins.registry import default_registry
from rehabkit.core.scenario.loader import load_scenario
from rehabkit.wholebody.stack import Level, solve_weighted

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS = [1000.0, 100.0, 10.0, 1.0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=0)
    ap.add_argument("--fifo", action="store_true",
                    help="run under SCHED_FIFO (as a robot's control thread would; needs the privilege)")
    ap.add_argument("--paced", action="store_true",
                    help="start a cycle every 2 ms (both solvers), sleeping in between, as a control loop does; "
                         "a busy loop under SCHED_FIFO is throttled by the kernel (50 ms in every second)")
    args = ap.parse_args()
    if args.fifo:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        os.sched_setaffinity(0, {os.cpu_count() - 1})
    sc = load_scenario(ROOT / "scenarios" / "coman_juggling.yaml").model
    reg = default_registry()
    robot = reg.get("robot", sc.robot.type).factory(sc.robot, None)
    ctx = Context(ROOT, np.random.default_rng(0), 0.001, robot=robot, world=sc.world)
    stack = reg.get("controller", sc.controller.type).factory(sc.controller, ctx)
    planner = reg.get("planner", sc.planner.type).factory(sc.planner, ctx)
    catch = np.eye(4)
    catch[:3, 3] = next(t.position for t in sc.task.targets if t.name == "catch")
    q0 = robot.standing
    plan = planner.plan(PlanRequest(0.0, q0, np.zeros(len(q0)), [Target("catch", pose=catch)] * 3, robot))
    n = args.cycles or int(plan.trajectory.duration * 1000)
    x, xd, _ = plan.trajectory.sample(np.arange(n) * 0.001)

    stack.compute(0.0, q0, np.zeros(len(q0)), x[0], xd[0], None)  # binds the tasks to the standing pose
    st = stack.state
    res_c, res_w, t_c, t_w, t_ref, qp_called = [], [], [], [], [], []
    # the machine's own jitter: one fixed 52x52 LAPACK solve (the largest KKT system), timed in the same loop
    kkt = np.random.default_rng(0).normal(size=(52, 52)) + 52 * np.eye(52)
    rhs = np.ones(52)
    next_tick = time.perf_counter()
    gc.disable()  # a collection in the middle of a cycle would be timed too; the controller runs with it enabled
    for k in range(n):
        calls = stack.solves.get("solver", 0)
        t0 = time.perf_counter_ns()
        v = stack.solve(x[k], xd[k])
        t_c.append(time.perf_counter_ns() - t0)
        qp_called.append(stack.solves.get("solver", 0) > calls)
        res_c.append(stack.last_residuals)
        # the weighted QP at the same state: same kinematics and rows, one solve
        t0 = time.perf_counter_ns()
        st.update(stack.q_des)
        ref = (stack.base_pose.act(x[k]), stack.base_pose.rotation @ xd[k])
        levels = []
        for tasks in stack.levels:
            rows = [t.rows(st, ref if t.spec.type == "frame" and t.spec.reference == "runner" else None)
                    for t in tasks]
            levels.append(Level(np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])))
        upper = pin.crba(st.model, st.data, stack.q_des)
        metric = np.triu(upper) + np.triu(upper, 1).T
        weighted = solve_weighted(levels, WEIGHTS, stack.constraints.build(st), stack.config.regularization,
                                  stack.config.solver, metric)
        t_w.append(time.perf_counter_ns() - t0)
        res_w.append(weighted.residuals)
        stack.q_des = pin.integrate(st.model, stack.q_des, v * 0.001)
        t0 = time.perf_counter_ns()
        np.linalg.solve(kkt, rhs)
        t_ref.append(time.perf_counter_ns() - t0)
        if args.paced:  # as a control loop runs: the next cycle starts at the next 2 ms tick (both solvers)
            next_tick += 0.002
            time.sleep(max(0.0, next_tick - time.perf_counter()))
    gc.enable()
    res_c, res_w = np.array(res_c), np.array(res_w)
    t_c, t_w, t_ref = np.array(t_c) / 1e6, np.array(t_w) / 1e6, np.array(t_ref) / 1e6

    print(f"machine: {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}")
    print(f"{n} cycles along three throws (COMAN, {stack.state.model.nv} velocities, "
          f"{len(stack.levels)} levels, solver {stack.config.solver})\n")
    names = [lv.name or f"level {i + 1}" for i, lv in enumerate(stack.config.levels)]
    print(f"{'level':16s} {'cascade mean':>13s} {'weighted mean':>14s} {'cascade max':>12s} {'weighted max':>13s} "
          f"{'cycles cascade <= weighted':>27s}")
    for i, name in enumerate(names):
        better = np.mean(res_c[:, i] <= res_w[:, i] + 1e-9)
        print(f"{name:16s} {res_c[:, i].mean():13.2e} {res_w[:, i].mean():14.2e} {res_c[:, i].max():12.2e} "
              f"{res_w[:, i].max():13.2e} {better:26.1%}")
    # lexicographic comparison: at the first level where the two differ (beyond 1e-9), the cascade must be better
    diff = res_c - res_w
    first = np.argmax(np.abs(diff) > 1e-9, axis=1)
    differs = np.any(np.abs(diff) > 1e-9, axis=1)
    ok = ~differs | (diff[np.arange(n), first] < 0)
    print(f"\npriority respected in {ok.mean():.2%} of cycles (at the highest level where the two solutions "
          "differ, the cascade's residual is the smaller)")
    print("levels where they first differ: " + ", ".join(
        f"{names[i]} {np.sum(differs & (first == i))}" for i in range(len(names))))
    print(f"\n{'cycle time [ms]':16s} {'median':>8s} {'p99':>8s} {'worst':>8s}")
    for name, t in (("cascade", t_c), ("weighted QP", t_w)):
        print(f"{name:16s} {np.median(t):8.3f} {np.percentile(t, 99):8.3f} {t.max():8.3f}")
    print(f"{'ratio':16s} {np.median(t_c) / np.median(t_w):8.2f} {np.percentile(t_c, 99) / np.percentile(t_w, 99):8.2f}"
          f" {t_c.max() / t_w.max():8.2f}")
    print(f"{'one 52x52 solve':16s} {np.median(t_ref):8.3f} {np.percentile(t_ref, 99):8.3f} {t_ref.max():8.3f}"
          "   (the machine's jitter: a fixed workload's worst case against its median)")
    qp_called = np.array(qp_called)
    print(f"\ncascade cycles over 1 ms: {np.sum(t_c > 1.0)} of {n} ({np.mean(t_c > 1.0):.2%}); "
          f"cycles where an inequality was active (QP solver called): {qp_called.sum()}, of which over 1 ms: "
          f"{np.sum(t_c[qp_called] > 1.0)}; scheduler: {'SCHED_FIFO' if args.fifo else 'default'}")
    if qp_called.any():
        print(f"cycles with the QP solver: median {np.median(t_c[qp_called]):.3f} ms, worst {t_c[qp_called].max():.3f}")


if __name__ == "__main__":
    main()
