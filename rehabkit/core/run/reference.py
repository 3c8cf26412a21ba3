"""The reference the controller follows, step by step, and the movements it is made of.

Plans are sampled once, at the control rate, into arrays from the step they start
at to the end of the run (past its end a trajectory holds its last value); a replan
overwrites from its own step on. Each plan is also cut into movements — one per
stretch between its waypoints, or the whole plan — whose goals are what a
(simulated) person aims for, and what the outcome measures call reaches.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from rehabkit.core.kinds.interfaces import Plan
from rehabkit.core.results.record import Movement


class ReferenceBuffer:
    """Position, velocity and acceleration references for ``steps`` control steps (``width`` wide).

    ``hand(x)`` maps a reference point to the hand's position (base frame): identity for Cartesian
    references, the robot's forward kinematics for joint ones.
    """

    RUN_STATE_FIELDS = ("pos", "vel", "acc", "goal", "goal_at", "movements")  # (what plans write: a snapshot's)

    def __init__(self, steps: int, start: np.ndarray, dt: float, hand: Callable[[np.ndarray], np.ndarray]):
        w = len(start)
        self.pos = np.tile(start, (steps + 1, 1))
        self.vel, self.acc = np.zeros((steps + 1, w)), np.zeros((steps + 1, w))
        self.steps, self.dt, self._hand = steps, dt, hand
        self.goal = np.array(start, float)
        self.goal_at = np.tile(start, (steps, 1))  # the goal of the movement under way, step by step
        self.movements: list[Movement] = []

    def views(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The references of the run's steps (views: later plans show up in them)."""
        n = self.steps
        return self.pos[:n], self.vel[:n], self.acc[:n]

    def sample(self, plan: Plan, k0: int) -> np.ndarray:
        """The plan's positions at the control rate from step ``k0`` to the end of the run."""
        return plan.trajectory.sample(np.arange(len(self.pos) - k0) * self.dt)[0]

    def install(self, k0: int, plan: Plan, names: Sequence[str] = ()) -> np.ndarray:
        """Follow ``plan`` (through the targets ``names``) from step ``k0``; returns its positions sampled from
        there."""
        x, xd, xdd = plan.trajectory.sample(np.arange(len(self.pos) - k0) * self.dt)
        self.pos[k0:], self.vel[k0:], self.acc[k0:] = x, xd, xdd
        self.goal = x[-1].copy()
        self.add_movements(k0, plan, x, names)
        return x

    def add_movements(self, k0: int, plan: Plan, x: np.ndarray, names: Sequence[str] = ()) -> None:
        """The plan's movements (a replan cuts the one under way); their goals from their start on. Each is named
        after the target it goes to, the last ones after the last ``names`` (a plan's own start point comes
        first, as the timeline counts them)."""
        self.movements = [m for m in self.movements if m.k0 < k0]
        if self.movements:
            self.movements[-1].k1 = min(self.movements[-1].k1, k0)
        times, way, dt = plan.waypoint_times, plan.waypoints, self.dt
        if times is not None and way is not None and len(times) == len(way) > 1:
            starts = [k0 + int(round(t / dt)) for t in times]
            new = [Movement(starts[i - 1], starts[i], self._hand(way[i]), np.asarray(way[i], float))
                   for i in range(1, len(way))]
            new[-1].k1 = self.steps  # the last one may settle after its end
        else:
            new = [Movement(k0, self.steps, self._hand(x[-1]), x[-1].copy())]
        for m, name in zip(reversed(new), reversed(names)):
            m.name = name
        for m in new:
            self.goal_at[m.k0 :] = m.target
        self.movements += new
