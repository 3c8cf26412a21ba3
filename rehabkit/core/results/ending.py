"""How a run ended, as ``summary.json`` says it (``ended``) and the exit code tells it apart.

- ``completed``: the run went to its end;
- ``stopped``: the safety layer stopped it (a limit, the keep-in box, the force, an e-stop, a refused plan);
- ``plugin-fault``: a plugin raised (the safety layer stopped the robot);
- ``backend-fault``: the backend could not drive the robot any more (a lost link or bus, a refused reset);
- ``interrupted``: Ctrl-C or SIGTERM (the robot brought to rest first, then the files closed).

A run killed outright (kill -9, the power) ends nowhere: ``rehabkit recover`` makes its folder from what it left,
``killed (recovered)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

How = Literal["completed", "stopped", "plugin-fault", "backend-fault", "interrupted", "killed (recovered)"]

# the exit code of each ending (completed: 0 when every expectation is met, else 1)
EXIT_CODES: dict[str, int] = {"stopped": 1, "plugin-fault": 3, "backend-fault": 4}
SIGNAL_EXITS = {"SIGINT": 130, "SIGTERM": 143}  # 128 + the signal's number, as shells report it


@dataclass(frozen=True)
class RunEnding:
    """How the run ended (``how``), why (``reason``, for people), at what time [s], the signal that ended it where
    one did, and the class name of the error that ended it (``error_type``) where one did."""

    how: How
    reason: str = ""
    t: float | None = None
    signal: str | None = None
    cut_short: bool = False  # the loop did not run its course (a signal, an error out of it): not a safety stop's end
    error_type: str | None = None  # (the error's class as a field: the reason says it in words)

    @property
    def words(self) -> str:
        """How it ended, in a sentence's words (``the run {words} at …``)."""
        return {"interrupted": f"was interrupted ({self.signal or 'SIGINT'})",
                "plugin-fault": "ended on a plugin's fault", "backend-fault": "ended on a backend fault",
                "stopped": "was stopped by the safety layer", "completed": "completed"}.get(self.how, self.how)

    @property
    def early(self) -> bool:
        """Cut short before the task could end (not a safety stop, which the verdicts judge as such): what was not
        reached can't pass."""
        return self.cut_short

    def exit_code(self, passed: bool) -> int:
        """The command's exit code for this ending."""
        if self.how == "interrupted":
            return SIGNAL_EXITS.get(self.signal or "SIGINT", 130)
        if self.how == "completed":
            return 0 if passed else 1
        return EXIT_CODES[self.how]

    def as_dict(self) -> dict:
        out = {"how": self.how, "reason": self.reason}
        if self.t is not None:
            out["t"] = round(self.t, 6)
        if self.signal is not None:
            out["signal"] = self.signal
        if self.error_type is not None:
            out["error_type"] = self.error_type
        return out


def ending_of(events: list, tripped_at: float | None) -> RunEnding:
    """How a run that went its course ended: by its first trip's rule (a plugin's, the backend's, any other), or
    completed."""
    if tripped_at is None or not events:
        return RunEnding("completed")
    first = events[0]
    how = {"plugin-error": "plugin-fault", "backend": "backend-fault"}.get(first.rule, "stopped")
    return RunEnding(how, first.message, first.t)
