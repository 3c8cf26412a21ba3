"""What the safety layer did and why: one event (a trip, a clipping episode, a ramp, the brakes)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


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

    def as_dict(self) -> dict:
        return asdict(self)
