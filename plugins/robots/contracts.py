"""What a planner or controller needs of one of the built-in robots beyond the shared contract, declared beside
those robots (a third party's robot offers them by deriving from them, as with the capabilities of
:mod:`rehabkit.plugin`)."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class ClusterPoints(Protocol):
    """Gives points on its moving body (robot.cluster_points), for collision maps."""

    def cluster_points(self, qs: np.ndarray) -> np.ndarray:
        """World points (n, k, 3) of the moving body at configurations ``qs`` (n, dof)."""
        ...


@runtime_checkable
class LiftArmGripper(Protocol):
    """Has a lift, an arm and a gripper (robot.lift_index, robot.arm, robot.gripper_index): a wheelchair-mounted
    arm's joints, as indices into ``q``."""

    lift_index: int
    arm: Any
    gripper_index: int
