"""What the safety layer did and why: one event (a trip, a clipping episode, a ramp, the brakes), and clipping steps
gathered into episodes."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # (annotation only: the event module stays free of the limit checks' imports)
    from rehabkit.core.safety.limit_breach import LimitBreach


@dataclass
class SafetyEvent:
    """Why the safety layer acted: a trip, a clipping episode or a ramp."""

    t: float
    rule: str
    joint: str | None
    value: float | None
    limit: float | None
    message: str
    data: dict = field(default_factory=dict)  # rule-specific values (a clipping episode's length, a box axis)
    level: str = "ERROR"  # how the log shows it: INFO (a ramp), WARN (clipping, a held command), ERROR (a stop)
    cause: str = ""  # what happened in the event's own words: the message without its time and the stop it led to
    # the joint limit broken where a limit rule tripped, or the one a refused plan or the bridge's own check names
    # (its quantity, and its unit: ``revolute``), else None. In memory only: the event's record (``as_dict``) keeps
    # the keys it had (its joint, value and limit are the breach's already)
    breach: LimitBreach | None = field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict:
        d = asdict(self)
        del d["breach"]  # (in memory only: summary.json and the safety log keep their keys)
        return d


class Clipping:
    """Torque clipping as interventions: steps clipped in a row (one control period apart) are one episode, its
    peak (the largest share of a joint's effort limit) and its length kept; a new episode is told to ``note``."""

    RUN_STATE_FIELDS = ("episode",)  # (a snapshot's)

    def __init__(self, names: list[str], effort: np.ndarray, dt: float, note: Callable[[SafetyEvent], None]):
        self.names, self.effort, self.dt, self.note = names, effort, dt, note
        self.episode: SafetyEvent | None = None  # the one under way

    def step(self, t: float, tau: np.ndarray, over: np.ndarray) -> None:
        """``tau`` was clipped at ``t`` where ``over``."""
        j = int(np.argmax(np.where(over, np.abs(tau) / self.effort, 0.0)))
        ep = self.episode
        if ep is not None and t - ep.data["until_s"] <= 1.5 * self.dt:
            ep.data["until_s"], ep.data["steps"] = t, ep.data["steps"] + 1
            if abs(tau[j]) / self.effort[j] > abs(ep.value) / ep.limit:
                ep.joint, ep.value, ep.limit = self.names[j], float(tau[j]), float(self.effort[j])
            return
        self.episode = SafetyEvent(t, "torque-clip", self.names[j], float(tau[j]), float(self.effort[j]),
                                   f"t={t:.3f}s: commanded torque clipped to the effort limit",
                                   {"until_s": t, "steps": 1}, level="WARN")
        self.note(self.episode)
