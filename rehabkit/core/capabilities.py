"""What a robot can do beyond the :class:`~rehabkit.core.interfaces.Robot` basics, declared, not guessed.

A robot plugin states a capability by deriving from its protocol
(``class MyArm(Robot, Gripper)``) and implementing it. A planner, controller or
sensor that needs one lists it in its class's ``requires`` attribute
(``requires = (ClusterPoints,)``); the run's setup — and ``rehabkit validate`` —
refuse a scenario whose robot lacks it, before anything else is built.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class WorkspaceTable(Protocol):
    """A voxel look-up table of the hand's workspace (robot base frame)."""


    def workspace(self, resolution: float = 0.01, progress: bool = True, use_cache: bool = True) -> Any:
        """The table (a :class:`rehabkit.workspace.grid.VoxelWorkspace`)."""
        ...


@runtime_checkable
class RandomReach(Protocol):
    """Draws reachable hand positions at random (``task.targets[].random``)."""


    def random_reach(self, rng: np.random.Generator, not_straight_from: np.ndarray | None = None) -> np.ndarray:
        """A hand position [m] (base frame) well inside the workspace; with ``not_straight_from``, one whose
        straight line from that point leaves the workspace (a reach that needs planning around)."""
        ...


@runtime_checkable
class PassiveJoints(Protocol):
    """A mechanism with joints that follow the driven ones (a parallel robot's passive joints)."""


    def passive_state(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Every simulated joint's value (by name) for driven joint values ``q``."""
        ...


@runtime_checkable
class ClusterPoints(Protocol):
    """Points on the moving body, for collision maps."""


    def cluster_points(self, qs: np.ndarray) -> np.ndarray:
        """World points (n, k, 3) of the moving body at configurations ``qs`` (n, dof)."""
        ...


@runtime_checkable
class FloatingBase(Protocol):
    """A floating-base robot (a humanoid): its model seen from the world, and a standing posture."""

    standing: np.ndarray

    @property
    def floating_model(self) -> Any:
        """The Pinocchio model with the free root joint."""
        ...


@runtime_checkable
class LiftArmGripper(Protocol):
    """A wheelchair-mounted arm: a lift joint, the arm's joints and a gripper joint (indices into ``q``)."""

    lift_index: int
    arm: Any
    gripper_index: int


ABILITY: dict[type, str] = {
    WorkspaceTable: "has a workspace look-up table (robot.workspace)",
    RandomReach: "draws random reachable targets (robot.random_reach)",
    PassiveJoints: "assembles its passive joints (robot.passive_state)",
    ClusterPoints: "gives points on its moving body (robot.cluster_points)",
    FloatingBase: "has a floating base (robot.floating_model, robot.standing)",
    LiftArmGripper: "has a lift, an arm and a gripper (robot.lift_index, robot.arm, robot.gripper_index)",
}


def missing_capabilities(factory: Any, robot: Any) -> list[str]:
    """What ``factory`` (a plugin class with ``requires``) needs of ``robot`` that it lacks, in words."""
    return [ABILITY.get(cap, cap.__name__) for cap in getattr(factory, "requires", ()) if not isinstance(robot, cap)]
