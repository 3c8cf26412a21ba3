"""The patient plugin kind: a simulated person at the robot's joints (:class:`Patient`), or one simulated as a body
in the backend's scene and strapped to the robot (:class:`EmbodiedPatient`). Re-exported by
:mod:`rehabkit.core.kinds.interfaces` and :mod:`rehabkit.plugin`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from pydantic import Field, model_validator

from rehabkit.core.kinds.backend import Drawing
from rehabkit.core.kinds.metric import Metric
from rehabkit.core.kinds.run_state import RunState
from rehabkit.core.kinds.trace import Trace
from rehabkit.models.strict import StrictModel


class JointRom(StrictModel):
    """Range of motion of one revolute joint [deg] and its comfortable speed [deg/s] (a prismatic joint has none: its
    limits are the safety envelope's, in metres): a patient profile's (``patient: joints:``), and a simulated
    person's own ranges."""

    passive_deg: tuple[float, float] = Field(description="range the joint can be moved through (a hard limit)")
    active_deg: tuple[float, float] | None = Field(None, description="range the person reaches on their own")
    max_speed_deg_s: float | None = Field(None, gt=0, description="comfortable speed of this joint")

    @model_validator(mode="after")
    def _nested(self) -> JointRom:
        lo, hi = self.passive_deg
        if lo >= hi:
            raise ValueError(f"passive_deg must be [lowest, highest], got {list(self.passive_deg)}")
        if self.active_deg is not None:
            a, b = self.active_deg
            if a >= b or a < lo or b > hi:
                raise ValueError(f"active_deg {list(self.active_deg)} must be an interval inside passive_deg "
                                 f"{list(self.passive_deg)}")
        return self


class Patient(RunState, ABC):
    """A simulated person at the robot's joints: the torques their arm applies, each control step.

    ``delay_s`` is how late the person perceives the task: the runner passes the goal of the
    movement under way (in the planner's space: a hand position or joint values) as it was that
    long ago.
    """

    delay_s: float = 0.0
    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of what run_metrics reports
    requires: ClassVar[tuple[type, ...]] = ()  # capabilities needed of the robot or backend (core.kinds.capabilities)
    # settings (over the plugin's own) that leave the person relaxed, no voluntary effort: a passive assessment's
    relaxed: ClassVar[dict[str, Any]] = {}

    @abstractmethod
    def torque(self, t: float, q: np.ndarray, qd: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Joint torques [N·m] the person applies to the robot now (positive along each joint's axis)."""

    def run_metrics(self, trace: Trace) -> dict[str, float]:
        """Figures about the person over the run (e.g. fatigue); default none."""
        return {}

    def inputs(self) -> dict[str, str]:
        """Fingerprints of what drove the person (e.g. a digest of the noise drawn), for replays; default none."""
        return {}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Internal states over time for the log, name → (times [s], values); default none."""
        return {}

    def drawing(self) -> dict[str, Drawing]:
        """What to draw of the person now (called at the log rate), name → shapes; default none."""
        return {}

    def state(self) -> np.ndarray:
        """The simulated person's inner state now, a fixed-length vector (what a learning environment's
        ``person_state`` term shows, e.g. fatigue); default empty."""
        return np.zeros(0)


class EmbodiedPatient(Patient):
    """A person simulated as a body in the backend's scene (a musculoskeletal arm) and strapped to the robot.

    A backend that hosts bodies (:class:`~rehabkit.core.kinds.capabilities.HostsBodies`) calls :meth:`compose` on its
    scene description before building it, :meth:`bind` on the built scene, and :meth:`place` at each reset, the
    robot at its start posture. :meth:`torque` then drives the person's own actuators for the coming control period
    and returns the torque their straps put on the robot's joints, for the record: the scene applies it.
    """

    @abstractmethod
    def compose(self, spec: Any) -> None:
        """Add the person's body and the straps to the scene description (a ``mujoco.MjSpec``)."""

    @abstractmethod
    def bind(self, model: Any, data: Any) -> None:
        """The built scene (``mujoco.MjModel``/``MjData``): look up what the steps will read and write."""

    @abstractmethod
    def place(self) -> None:
        """Fit the person to the robot as it stands now (called by the backend's reset)."""

    def joint_torque(self, q: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        """The robot's joint torques [N·m] from ``force`` (world frame) acting where the strap pressing hardest
        now is fastened (how hard a force there can drive each joint); default None (unknown)."""
        return None

    def interaction_torque(self) -> np.ndarray | None:
        """Every strap's force on the robot now, as torques on its joints [N·m] (a retreat moves away along them);
        default None (unknown)."""
        return None

    @abstractmethod
    def interaction_force(self) -> np.ndarray:
        """The largest strap force now, world frame [N]: what the safety envelope's force limit checks."""
