"""Run metrics from the recorded trace, and the ``expect:`` verdicts."""

from __future__ import annotations

import numpy as np

from rehabkit.core.kinds.names import suggest
from rehabkit.core.kinds.trace import Trace
from rehabkit.core.scenario.models import Bound
from rehabkit.models.robot_model import RobotModel


def tracking_metrics(trace: Trace, robot_plugin, goal_q: np.ndarray | None) -> tuple[dict, dict]:
    """Scalar metrics and per-joint figures of how the robot followed its reference."""
    robot: RobotModel = robot_plugin.model
    turns = np.asarray(robot.revolute, bool)  # (each joint in its own unit: degrees, or metres where it slides)
    scale = np.where(turns, np.degrees(1.0), 1.0)
    err = (trace.q_ref - trace.q) * scale
    deg = err[:, turns] if err.size else err
    metrics = {
        "tracking_rms_deg": float(np.sqrt(np.mean(deg**2))) if deg.size else float("nan"),
        "tracking_max_deg": float(np.abs(deg).max()) if deg.size else float("nan"),
        "max_velocity_ratio": float(np.max(np.abs(trace.qd) / robot.limits.velocity)) if err.size else 0.0,
        "max_torque_ratio": float(np.max(np.abs(trace.tau) / robot.limits.effort)) if err.size else 0.0,
    }
    if err.size and not turns.all():
        metrics["tracking_max_m"] = float(np.abs(err[:, ~turns]).max())
    per_joint = {
        name: {
            f"tracking_rms_{u}": float(np.sqrt(np.mean(err[:, j] ** 2))),
            f"tracking_max_{u}": float(np.abs(err[:, j]).max()),
            f"range_{u}": [float(trace.q[:, j].min() * scale[j]), float(trace.q[:, j].max() * scale[j])],
        }
        for j, (name, u) in enumerate(zip(robot.joint_names, ["deg" if t else "m" for t in turns], strict=True))
    } if err.size else {}
    if trace.q_ctrl is not None and (rows := np.isfinite(trace.q_ctrl).all(axis=1)).any():
        own = (trace.q_ctrl[rows] - trace.q[rows]) * scale  # what the controller meant, e.g. a compliant yield
        if turns.any():
            metrics["controller_tracking_rms_deg"] = float(np.sqrt(np.mean(own[:, turns] ** 2)))
            metrics["controller_tracking_max_deg"] = float(np.abs(own[:, turns]).max())
        if not turns.all():
            metrics["controller_tracking_max_m"] = float(np.abs(own[:, ~turns]).max())
    metrics["joint_limit_excess_deg"] = joint_limit_excess(trace, robot)
    if not turns.all():
        metrics["joint_limit_excess_m"] = joint_limit_excess(trace, robot, revolute=False)
    if goal_q is not None and err.size:
        q_end = trace.q[-1]
        off, turns = np.abs(goal_q - q_end), np.asarray(robot.revolute, bool)
        if turns.any():
            metrics["final_joint_error_deg"] = float(np.degrees(off[turns]).max())
        if not turns.all():  # (a prismatic joint's, in metres)
            metrics["final_joint_error_m"] = float(off[~turns].max())
        ee = robot_plugin.ee_world(np.vstack([goal_q, q_end]))
        metrics["final_position_error_m"] = float(np.linalg.norm(ee[0] - ee[1]))
    return metrics, per_joint


def joint_limit_excess(trace: Trace, robot: RobotModel, revolute: bool = True) -> float:
    """Largest excursion of any revolute joint beyond its range over the run [deg] (0 if none); with ``revolute``
    False, of any prismatic joint [m]."""
    which = np.asarray(robot.revolute, bool) == revolute
    if not len(trace.q) or not which.any():
        return 0.0
    over = np.maximum(trace.q - robot.limits.upper, robot.limits.lower - trace.q)[:, which]
    worst = max(0.0, float(over.max()))
    return float(np.degrees(worst)) if revolute else worst


def evaluate(expect: dict[str, Bound], metrics: dict[str, float]) -> list[dict]:
    """One verdict per expectation; a metric the run did not produce fails, naming the closest ones."""
    out = []
    for key, bound in expect.items():
        value = metrics.get(key)
        entry = {"metric": key, "bound": bound.describe(), "value": value}
        if value is None:
            entry.update(passed=False, reason=f"the run produced no metric '{key}'{suggest(key, metrics)}")
        else:
            entry["passed"] = bound.check(float(value))
        out.append(entry)
    return out
