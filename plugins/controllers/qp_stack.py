"""Whole-body control by a stack of QPs at the control rate (after Mohammadi et al.), for floating robots.

Each cycle: Pinocchio kinematics of the stack's own configuration, each level's task
rows, the inequalities (joint limits as a velocity damper, joint speeds, CoM height,
CoM inside the support polygon), the cascade of QPs (``rehabkit.wholebody.stack``),
then the velocity is integrated into the joint reference. The robot is servoed to it
by joint PD plus the torques that hold it standing on its feet. Levels and tasks
come from YAML, in priority order: add, remove or reorder them without code.

A ``frame`` task with ``reference: runner`` follows the scenario planner's Cartesian
reference (positions in the robot's base frame, e.g. a throw for the hand).
"""

from __future__ import annotations

import time
from typing import Literal

import numpy as np
import pinocchio as pin
from pydantic import Field

from rehabkit.control import (
    Constraints,
    ConstraintSpec,
    KinematicState,
    Level,
    Task,
    TaskSpec,
    compile_kernels,
    solve_cascade,
)
from rehabkit.plugin import Context, Controller, FloatingBase, Metric, StrictModel, hookimpl


class LevelSpec(StrictModel):
    """One priority level: its tasks share it softly (weights)."""

    name: str = ""
    tasks: list[TaskSpec] = Field(min_length=1)


class QpStackConfig(StrictModel):
    """Levels (highest priority first), the inequalities they all obey, the solver and the servo."""

    levels: list[LevelSpec] = Field(min_length=1)
    constraints: ConstraintSpec = ConstraintSpec()
    solver: Literal["daqp", "proxqp"] = "daqp"
    regularization: float = Field(1e-6, gt=0, description="ε of each level's damping ½ε‖v‖²")
    metric: Literal["kinetic-energy", "identity"] = Field(
        "kinetic-energy", description="among the optima, the least ½vᵀHv: H the joint-space inertia matrix "
                                      "(kinetic energy, eq. 1) or the identity (minimum norm)")
    kp: float = Field(300.0, gt=0, description="joint servo stiffness [N·m/rad]")
    kd: float = Field(5.0, ge=0, description="joint servo damping [N·m·s/rad]")


class QpStack(Controller):
    """Cascade of velocity-level QPs (strict priorities, soft weights within a level), PD servo."""

    RUN_STATE_NESTED = ("state",)  # (its kinematic state, changed in place: a session snapshot takes it)

    metrics = (
        Metric("qp_cycles", "count", description="control cycles of the QP cascade"),
        Metric("qp_cycles_over_1ms", "count", description="cycles whose cascade took over 1 ms", clock="wall"),
        Metric("qp_failed_cycles", "count", description="cycles where a level's QP failed"),
        Metric("qp_level*_max_residual", description="largest task residual of a level"),
        Metric("qp_solver_calls_share", description="share of cycles that called the QP solver"),
    )

    reference = "cartesian"
    requires = (FloatingBase,)

    def __init__(self, config: QpStackConfig, context: Context):
        robot = context.robot
        self.config, self.robot, self.dt = config, robot, context.control_dt
        self.state = KinematicState(robot.floating_model)
        self.q_des = robot.pin_configuration(np.zeros(robot.model.dof))
        self._configure(self.q_des)
        self.warm: list[np.ndarray | None] = []
        self.cycle_ns: list[int] = []  # ints: no work for the garbage collector
        self.failures = 0
        self.solves: dict[str, int] = {}
        self.last_residuals: list[float] = []  # per level, of the latest cycle
        self.max_residuals = np.zeros(len(config.levels))  # per level, over the run
        self.joint_reference = None
        self._started = False
        compile_kernels()  # here, not in the first timed cycle

    def _configure(self, q_full: np.ndarray) -> None:
        """Bind tasks and constraints to the starting configuration (held tasks keep it)."""
        self.state.update(q_full)
        names = self.robot.model.joint_names
        self.levels = [[Task(t, self.state, names) for t in lv.tasks] for lv in self.config.levels]
        # every task's rows are filled in place each cycle into one array the levels are views of (np.vstack of
        # the tasks' rows, then of the levels', cost ~50 us a cycle); a posture task's rows are constant: only b
        rows = [[t.rows(self.state, None) for t in tasks] for tasks in self.levels]
        self._A = np.vstack([A for level in rows for A, _ in level])
        self._b = np.concatenate([b for level in rows for _, b in level])
        self._ends = np.cumsum([sum(len(b) for _, b in level) for level in rows])
        self._levels = [Level(self._A[a:e], self._b[a:e]) for a, e in zip([0, *self._ends[:-1]], self._ends)]
        cuts = np.cumsum([0, *(len(b) for level in rows for _, b in level)])
        self._task_rows = [(t, self._A[a:e], self._b[a:e])
                           for t, a, e in zip([t for tasks in self.levels for t in tasks], cuts[:-1], cuts[1:])]
        # the kinetic-energy choice only matters if the levels leave some velocity free (generically)
        self._freedom_left = len(self._b) < self.state.model.nv
        lim = self.robot.model.limits
        self.constraints = Constraints(self.config.constraints, self.state, lim.lower, lim.upper, lim.velocity)
        self.base_pose = pin.SE3(self.robot.model.base_pose[:3, :3], self.robot.model.base_pose[:3, 3])
        self._base_rotation = self.base_pose.rotation  # kept: Pinocchio's accessor wraps a new view on every call

    def solve(self, x_ref: np.ndarray | None, xd_ref: np.ndarray | None) -> np.ndarray:
        """One cycle of the stack at the current reference configuration: the generalised velocity."""
        st = self.state
        st.update(self.q_des)
        ref = None
        if x_ref is not None:  # runner references are in the base frame; tasks work in the world
            ref = (self.base_pose.act(np.asarray(x_ref, float)), self._base_rotation @ np.asarray(xd_ref, float))
        for task, A, b in self._task_rows:
            task.fill(st, ref if task.follows_runner else None, A, b)
        metric = None
        if self.config.metric == "kinetic-energy" and self._freedom_left:
            upper = pin.crba(st.model, st.data, self.q_des)  # Pinocchio fills the upper triangle only
            metric = np.triu(upper) + np.triu(upper, 1).T
        result = solve_cascade(self._levels, self.constraints.build(st), self.config.regularization, self.config.solver,
                               self.warm, metric, self.solves, stacked=(self._A, self._b, self._ends))
        if result.failed_levels:
            self.failures += 1
        self.last_residuals = result.residuals
        np.maximum(self.max_residuals, result.residuals, out=self.max_residuals)
        return result.v

    def compute(self, t, q, qd, q_ref, qd_ref, qdd_ref):
        if not self._started:  # the stack starts from where the robot stands
            self.q_des = self.robot.pin_configuration(np.asarray(q, float).copy())
            self._configure(self.q_des)
            self._started = True
        t0 = time.perf_counter_ns()
        v = self.solve(q_ref, qd_ref)
        self.cycle_ns.append(time.perf_counter_ns() - t0)
        self.q_des = pin.integrate(self.state.model, self.q_des, v * self.dt)
        joints = self.q_des[7:]
        self.joint_reference = joints
        return self.config.kp * (joints - q) + self.config.kd * (v[6:] - qd) + self.robot.support_torque(self.q_des)

    def run_metrics(self, trace) -> dict[str, float]:
        if not self.cycle_ns:
            return {}
        ms = np.array(self.cycle_ns) / 1e6
        return {"qp_cycles": float(len(ms)), "qp_cycle_median_ms": float(np.median(ms)),
                "qp_cycle_p99_ms": float(np.percentile(ms, 99)), "qp_cycle_max_ms": float(ms.max()),
                "qp_cycles_over_1ms": float(np.sum(ms > 1.0)),
                "qp_failed_cycles": float(self.failures),
                **{f"qp_level{i + 1}_max_residual": float(r) for i, r in enumerate(self.max_residuals)},
                "qp_solver_calls_share": self.solves.get("solver", 0) / max(1, sum(self.solves.values()))}


@hookimpl
def rehabkit_register_controllers(registry) -> None:
    registry.add("qp-stack", config=QpStackConfig, factory=QpStack)
