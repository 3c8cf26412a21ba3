"""Base classes of the plugin kinds (planner, controller; robot, sensor, backend and patient in
:mod:`rehabkit.core.kinds.robot`, :mod:`rehabkit.core.kinds.sensor`, :mod:`rehabkit.core.kinds.backend` and
:mod:`rehabkit.core.kinds.patient`, re-exported here) and the small types they exchange. Third parties import all of
them from :mod:`rehabkit.plugin`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

from rehabkit.core.kinds.backend import Backend, BackendFaultError, BodyPoses, Contact, Drawing, GeomVisual
from rehabkit.core.kinds.context import Context, ReferenceSpace
from rehabkit.core.kinds.errors import PlanningError, SettingError
from rehabkit.core.kinds.metric import Metric
from rehabkit.core.kinds.patient import EmbodiedPatient, JointRom, Patient
from rehabkit.core.kinds.robot import IKUnavailableError, Robot
from rehabkit.core.kinds.run_state import RunState
from rehabkit.core.kinds.sensor import Instrument, InteractionForceSensor, Reading, Sensor, SensorConfig
from rehabkit.core.kinds.trace import Trace
from rehabkit.models.strict import StrictModel


class Trajectory(Protocol):
    """A reference in the planner's space (joint values, or hand positions in the robot base frame):
    ``sample`` is vectorised over times [s] from its start."""

    duration: float

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities, accelerations, each ``(len(t), dof)``; held constant past the end."""
        ...


@dataclass
class Target:
    """A resolved task target.

    Attributes:
        name: Its name in the scenario.
        q: Joint values [rad], when given in joint space or solved by IK.
        pose: 4x4 base-frame pose, when Cartesian (orientation may be absent: ``position_only``).
        position_only: The target constrains position only.
    """

    name: str
    q: np.ndarray | None = None
    pose: np.ndarray | None = None
    position_only: bool = False
    same_as: str | None = None  # resolved alias: reuse that target's joint solution
    free_axes: str = ""  # tool axes the orientation may turn about (a pointing target: "z")
    hint: str = ""  # what may be wrong with how it was written (a posture in radians), said with a refusal of it

    @property
    def free(self) -> str:
        """The tool rotation axes left free by this target: ``"xyz"`` for a position alone."""
        return "xyz" if self.position_only else self.free_axes


@dataclass
class PlanRequest:
    """What a planner is asked: from the current state, through the targets."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    targets: list[Target]
    robot: Robot


@dataclass
class Plan:
    """A planner's answer.

    Attributes:
        trajectory: The reference in the planner's space (see :class:`Planner`), from the request time.
        diagnostics: Scalar figures merged into the run's metrics (e.g. continuity residuals).
        waypoints: The via points actually used, in the planner's space (for the summary and the log).
        details: Non-scalar results for the summary (e.g. an optimiser's history).
        actions: Things to do to the scene while the plan runs: ``(t, "release" | "grasp", object)``,
            ``t`` from the plan's start (e.g. a throw lets go of the ball at its release instant).
        waypoint_times: When the trajectory passes each of ``waypoints`` [s from its start]; each stretch
            between two is a reach for the outcome measures (default: the whole plan is one reach).
    """

    trajectory: Trajectory
    diagnostics: dict[str, float] = field(default_factory=dict)
    waypoints: np.ndarray | None = None
    details: dict[str, Any] = field(default_factory=dict)
    actions: list[tuple[float, str, str]] = field(default_factory=list)
    waypoint_times: np.ndarray | None = None  # when it passes each waypoint [s from its start]: the reaches counted


ControllerReference = Literal["joint", "cartesian", "own"]  # a controller's: the plan's space, or its own


class Planner(RunState, ABC):
    """Computes a trajectory at start and on task events.

    ``space`` says what the trajectory holds: joint values (``dof`` wide) or
    end-effector positions in the robot base frame (3 wide).
    """

    space: ClassVar[ReferenceSpace] = "joint"
    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of its diagnostics and run_metrics
    requires: ClassVar[tuple[type, ...]] = ()  # capabilities needed of the robot or backend (core.kinds.capabilities)

    @abstractmethod
    def plan(self, request: PlanRequest) -> Plan:
        """Plan from ``request.q`` through ``request.targets``."""

    def run_metrics(self, trace: Trace) -> dict[str, float]:
        """Figures about the executed run only this planner can judge (default none)."""
        return {}

    def visuals(self) -> dict[str, np.ndarray]:
        """Point sets worth drawing once (robot base frame), e.g. a workspace; default none."""
        return {}

    def joint_space_visuals(self) -> dict[str, np.ndarray]:
        """Point sets in joint space [rad] worth drawing once (3-DoF robots), e.g. obstacles; default none."""
        return {}


class Controller(RunState, ABC):
    """Turns a reference and the measured state into joint torques, at the control rate.

    ``reference`` is what it follows: the plan's references in ``"joint"`` or ``"cartesian"`` space (see
    :class:`Planner`), or ``"own"``: a reference it makes itself, ignoring the plan's (an HMI driven by a person's
    key presses, a passive stretch; such a controller asks for joint-space plans through ``Context.plan``).
    A controller that turns the plan into a joint reference of its own (closed-loop IK) or makes one exposes its
    current value as ``joint_reference``: the run records it as what was tracked, where the controller makes it.
    """

    reference: ClassVar[ControllerReference] = "joint"
    joint_reference: np.ndarray | None = None  # the joint reference it tracks now, where it builds one
    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of what run_metrics reports
    requires: ClassVar[tuple[type, ...]] = ()  # capabilities needed of the robot or backend (core.kinds.capabilities)

    def run_metrics(self, trace: Trace) -> dict[str, float]:
        """Figures about the executed run only this controller can judge (default none)."""
        return {}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Internal states over time for the log, name → (times [s], values); default none."""
        return {}

    tunable: ClassVar[tuple[str, ...]] = ()  # settings a learner may change during a run (see :meth:`tune`)

    def tune(self, values: dict[str, float]) -> None:
        """Change settings named in :attr:`tunable` from now on (a policy acting on the controller's parameters)."""
        if unknown := [k for k in values if k not in self.tunable]:
            raise ValueError(f"controller {type(self).__name__} cannot tune {', '.join(unknown)}; it tunes "
                             f"{', '.join(self.tunable) or 'nothing'}")

    @abstractmethod
    def compute(
        self, t: float, q: np.ndarray, qd: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray
    ) -> np.ndarray:
        """Joint torques [N·m]; called in the hot loop, so keep it allocation-light."""


__all__ = [  # the backend, sensor and patient kinds live in modules of their own; importable from here as before
    "Backend", "BackendFaultError", "BodyPoses", "Contact", "Context", "Controller", "Drawing", "EmbodiedPatient",
    "GeomVisual",
    "IKUnavailableError", "JointRom",
    "Instrument", "InteractionForceSensor", "Patient", "Plan", "Planner", "PlanningError", "SettingError",
    "PlanRequest", "Reading",
    "ReferenceSpace", "ControllerReference", "Robot", "Sensor", "SensorConfig", "StrictModel", "Target", "Trajectory",
]
