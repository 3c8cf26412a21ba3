"""How a person's arm sits in a robot: where their shoulder centre goes and where the straps hold them.

An exoskeleton declares this once (:attr:`RobotModel.wearable`); a user's own robot can declare it in its
scenario instead (the musculoskeletal patient's ``fit`` settings). A musculoskeletal patient reads it to put
the person's glenohumeral centre at :attr:`Wearable.shoulder`, turn their arm onto the robot's segments, and
strap each segment to the robot body named by a :class:`Strap`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Segment = Literal["upper_arm", "forearm", "hand"]


@dataclass(frozen=True)
class Strap:
    """A cuff (or a handle the hand holds) on a robot body.

    Attributes:
        segment: The person's segment it holds.
        body: The robot's MJCF body carrying it.
        position: Its centre in that body's frame [m].
    """

    segment: Segment
    body: str
    position: tuple[float, float, float]


@dataclass(frozen=True)
class Wearable:
    """Where the person goes in the robot.

    Attributes:
        shoulder: The person's shoulder (glenohumeral) centre in the robot base frame [m]; on a shoulder
            exoskeleton, where its shoulder axes meet.
        forward: The person's forward direction in the robot base frame (unit vector).
        up: The person's upward direction in the robot base frame (unit vector).
        straps: The cuffs holding the arm.
    """

    shoulder: tuple[float, float, float]
    forward: tuple[float, float, float]
    up: tuple[float, float, float]
    straps: tuple[Strap, ...]

    def person_axes(self) -> np.ndarray:
        """3×3 whose columns are the person's forward, left and up directions in the robot base frame (``forward``
        made exactly perpendicular to ``up``)."""
        f, u = np.asarray(self.forward, float), np.asarray(self.up, float)
        if not (np.linalg.norm(f) > 1e-9 and np.linalg.norm(u) > 1e-9):
            raise ValueError("wearable: 'forward' and 'up' must be directions (not zero)")
        f, u = f / np.linalg.norm(f), u / np.linalg.norm(u)
        if abs(f @ u) > 0.2:
            raise ValueError("wearable: 'forward' and 'up' must be perpendicular (they are "
                             f"{np.degrees(np.arccos(np.clip(f @ u, -1, 1))):.0f}° apart)")
        f = f - (f @ u) * u
        f /= np.linalg.norm(f)
        return np.column_stack([f, np.cross(u, f), u])
