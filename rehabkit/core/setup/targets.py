"""Task targets: from the DSL to joint values, with IK where a target is Cartesian."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rehabkit.core.kinds.capabilities import RandomReach
from rehabkit.core.kinds.errors import with_fix
from rehabkit.core.kinds.interfaces import PlanningError, Robot, Target
from rehabkit.core.scenario.models import TaskSpec
from rehabkit.models.chain import rpy_to_matrix


def resolve_targets(task: TaskSpec, robot: Robot, seed: int = 0) -> dict[str, Target]:
    """Every named target as a :class:`Target` (joint values and/or a base-frame pose).

    A ``random`` target draws from the robot's workspace table with its own stream of the
    scenario seed (``seed``, the target's index), so a sweep over seeds gets reproducible targets.
    """
    specs = {t.name: t for t in task.targets}
    index = {t.name: i for i, t in enumerate(task.targets)}
    out: dict[str, Target] = {}

    def get(name: str, stack: tuple[str, ...] = ()) -> Target:
        if name in out:
            return out[name]
        if name in stack:
            raise PlanningError(f"target '{name}' refers to itself through {' -> '.join((*stack, name))}", target=name)
        spec = specs[name]
        if spec.sensor:
            tgt = Target(name, position_only=True)  # its position arrives with the sensor's readings
        elif spec.same_as:
            ref = get(spec.same_as, (*stack, name))
            tgt = Target(name, q=None if ref.q is None else ref.q.copy(),
                         pose=None if ref.pose is None else ref.pose.copy(), position_only=ref.position_only,
                         same_as=ref.same_as or ref.name, free_axes=ref.free_axes)
        elif spec.random is not None:
            if not isinstance(robot, RandomReach):
                raise PlanningError(f"target '{name}': random targets need a robot that draws reachable points "
                                    f"('{robot.model.name}' does not)", target=name)
            rng = np.random.default_rng([seed, index[name]])
            start = None
            if spec.random.not_straight_from is not None:
                ref = get(spec.random.not_straight_from, (*stack, name))
                if ref.pose is None:
                    raise PlanningError(f"target '{name}': '{spec.random.not_straight_from}' has no position",
                                        target=name)
                start = ref.pose[:3, 3]
            point = robot.random_reach(rng, start)
            pose = np.eye(4)
            pose[:3, 3] = point
            tgt = Target(name, pose=pose, position_only=True)
        elif spec.joints_deg is not None or spec.joints_rad is not None or spec.joints is not None:
            q = posture_si(name, spec, robot.model)
            if len(q) != robot.model.dof:
                names = robot.model.joint_names
                sliding = spec.joints_deg is not None and not np.all(robot.model.revolute)  # (then: joints)
                raise PlanningError(f"target '{name}' has {len(q)} joint values; robot '{robot.model.name}' has "
                                    f"{robot.model.dof} joints, one value each in this order: {', '.join(names)}",
                                    target=name, fix="with a prismatic joint among them, as `joints: [...]` (degrees "
                                    "for the revolute ones, metres for the prismatic)" if sliding else "")
            hint = radians_hint(spec.joints_deg if spec.joints_deg is not None else spec.joints, robot.model.revolute,
                                "joints_deg" if spec.joints_deg is not None else "joints")
            tgt = Target(name, q=q, pose=robot.fk(q), hint=f"its joint values {hint}" if hint else "")
        else:
            pose = np.eye(4)
            pose[:3, 3] = spec.position
            position_only = False
            if spec.orientation_of:
                ref = get(spec.orientation_of, (*stack, name))
                if ref.pose is None or ref.position_only:
                    raise PlanningError(f"target '{name}': '{spec.orientation_of}' has no orientation to copy",
                                        target=name)
                pose[:3, :3] = ref.pose[:3, :3]
                hint = ref.hint.replace("its joint values", f"its orientation is {spec.orientation_of}'s, whose joint "
                                        "values", 1)
            elif spec.rpy_deg is not None:
                pose[:3, :3] = rpy_to_matrix(np.radians(spec.rpy_deg))
            else:
                position_only = True
            tgt = Target(name, pose=pose, position_only=position_only, free_axes=spec.free_axes or "",
                         hint=hint if spec.orientation_of else "")
        out[name] = tgt
        return tgt

    for name in specs:
        get(name)
    return out


def angular_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-joint difference ``a - b`` wrapped to (-π, π]."""
    return (np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi


@dataclass
class JointWaypoints:
    """Joint values for a target sequence, and how well IK reproduced Cartesian ones."""

    q: np.ndarray  # (n, dof)
    ik_position_error_m: float
    ik_orientation_error_deg: float
    ik_branches: dict[str, int]


def joint_waypoints(targets: list[Target], robot: Robot, q_start: np.ndarray,
                    accept: Callable[[np.ndarray], bool] | None = None) -> JointWaypoints:
    """Joint values for each target; Cartesian ones by IK, nearest branch to the previous point.

    The chosen branch is unwrapped relative to the previous waypoint so the arm
    takes the short way round, then checked against the joint limits and ``accept`` (a planner's test, e.g.
    free of the world's obstacles).
    """
    lim = robot.model.limits
    prev = np.asarray(q_start, dtype=float)
    rows, pos_err, rot_err, branches = [], 0.0, 0.0, {}
    solved: dict[str, np.ndarray] = {}  # a target visited again keeps its configuration
    for tgt in targets:
        if tgt.q is not None:
            q = tgt.q
        elif (tgt.same_as or tgt.name) in solved:
            q = solved[tgt.same_as or tgt.name]
        else:
            try:
                sols = robot.solve_ik(tgt.pose, reference=prev, free=tgt.free)
            except NotImplementedError as exc:  # no IK of its own and a model Pinocchio can't load
                raise PlanningError(f"target '{tgt.name}' is Cartesian: {exc}", target=tgt.name,
                                    fix="give it as joint values") from exc
            if not sols:
                said, fix = _unreachable(tgt, robot)
                raise PlanningError(said, target=tgt.name, fix=fix, code="out-of-reach")
            sols = [prev + angular_distance(s, prev) for s in sols]
            inside = [s for s in sols if np.all(s >= lim.lower) and np.all(s <= lim.upper)]
            if not inside:
                raise PlanningError(f"target '{tgt.name}': none of {len(sols)} IK solutions is within the joint limits",
                                    target=tgt.name)
            if accept is not None:
                inside = [s for s in inside if accept(s)]
                if not inside:
                    raise PlanningError(f"target '{tgt.name}': each of its IK solutions within the joint limits "
                                        "touches the world (an obstacle or the floor)", target=tgt.name)
            q = min(inside, key=lambda s: float(np.linalg.norm(s - prev)))
            branches[tgt.name] = len(sols)
            reached = robot.fk(q)
            pos_err = max(pos_err, float(np.linalg.norm(reached[:3, 3] - tgt.pose[:3, 3])))
            if not tgt.position_only:
                rot_err = max(rot_err, axis_error_deg(reached[:3, :3], tgt.pose[:3, :3], tgt.free_axes))
        rows.append(np.asarray(q, dtype=float))
        solved.setdefault(tgt.same_as or tgt.name, rows[-1])
        prev = rows[-1]
    return JointWaypoints(np.array(rows), pos_err, rot_err, branches)


def angle_axis(R: np.ndarray) -> tuple[float, np.ndarray | None]:
    """The turn of rotation matrix ``R`` [rad] and its unit axis (``None`` for no turn; near a half turn the axis is
    the eigenvector for eigenvalue 1)."""
    angle = float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    if angle < 1e-12:
        return 0.0, None
    if np.sin(angle) < 1e-6:
        w, v = np.linalg.eigh(R + R.T)
        return angle, v[:, np.argmax(w)]
    return angle, np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2 * np.sin(angle))


def axis_error_deg(reached: np.ndarray, wanted: np.ndarray, free: str = "") -> float:
    """Rotation error [deg] between two orientations, about the tool axes not in ``free`` (the components of the
    rotation vector taking ``reached`` to ``wanted``, in the tool frame, as the numeric IK measures it)."""
    angle, axis = angle_axis(reached.T @ wanted)
    kept = [i for i, name in enumerate("xyz") if name not in free]
    if not kept or axis is None:
        return 0.0
    if not free or np.pi - angle < 1e-6:  # the whole turn (near a half turn the axis's sign is ill-defined: bound it)
        return float(np.degrees(angle))
    return float(np.degrees(angle * np.abs(axis[kept]).max()))


def unreachable(target: Target, robot: Robot) -> str:
    """Why ``target`` has no joint solution, with how near the numeric IK came when it tried."""
    return with_fix(*_unreachable(target, robot))


def _unreachable(target: Target, robot: Robot) -> tuple[str, str]:
    """:func:`unreachable`'s message and its fix (the target's hint, where it has one) apart."""
    where = np.round(target.pose[:3, 3], 4).tolist()
    what = "position" if target.position_only else "pose"
    closest = robot.ik_closest_m
    near = f"; the closest the hand came is {closest * 1000:.0f} mm away" if np.isfinite(closest) and \
        closest > 1e-3 else ""
    if target.hint:
        return (f"target '{target.name}' at {where} m is out of reach: no {what} solution within the joint "
                f"limits{near}", target.hint)
    return (f"target '{target.name}' at {where} m is out of reach: no {what} solution within the joint "
            f"limits{near} (base frame; check the robot's base and the target's units)", "")


def posture_si(name: str, spec, model) -> np.ndarray:
    """A posture target's joint values in SI (radians, metres), from the form it is written in: ``joints`` each in
    its joint's unit (degrees for revolute, metres for prismatic), ``joints_rad`` SI, ``joints_deg`` degrees — which
    a prismatic joint cannot take (a finger's 0.02 meant in metres was 0.35 mm)."""
    revolute = np.asarray(model.revolute, bool)
    if spec.joints_rad is not None:
        return np.asarray(spec.joints_rad, float)
    values = np.asarray(spec.joints if spec.joints is not None else spec.joints_deg, float)
    if len(values) != len(revolute):
        return np.radians(values) if spec.joints is None else values  # (the count is said by the caller)
    if spec.joints is None and not revolute.all():
        sliding = [n for n, r in zip(model.joint_names, revolute, strict=True) if not r]
        hint = radians_hint(values, revolute, "joints")
        raise PlanningError(f"target '{name}': joints_deg gives every joint in degrees, and {', '.join(sliding)} "
                            f"{'is' if len(sliding) == 1 else 'are'} prismatic (metres): write this posture as "
                            "`joints: [...]`, degrees for the revolute joints and metres for the prismatic ones"
                            + (f"; its revolute values {hint}" if hint else ""), target=name,
                            code="prismatic-in-degrees")
    return np.where(revolute, np.radians(values), values)


def looks_like_radians(values_deg, revolute) -> bool:
    """Values given as degrees whose revolute ones are all within ±2π, not all near zero (a posture of a few degrees
    at most is rare; radians are common)."""
    v = np.abs(np.asarray(values_deg, float)[np.asarray(revolute, bool)])
    return bool(len(v)) and 0.2 <= v.max() <= 2 * np.pi


def radians_hint(values_deg, revolute, key: str = "joints_deg") -> str:
    """Why a posture given in degrees may be radians (its values "are all within ±2π: ..."; "" where not): every
    revolute value within ±2π, not all near zero (a posture of a few degrees at most is rare; radians are common).
    ``key``: the form the fix names (``joints_deg``, or ``joints``, which takes degrees for the revolute joints)."""
    if values_deg is None or not looks_like_radians(values_deg, revolute):
        return ""
    takes = "joints_deg takes degrees" if key == "joints_deg" else "joints takes degrees for a revolute joint"
    return f"are all within ±2π: written in radians? {takes} (joints_rad takes SI: radians, and metres)"
