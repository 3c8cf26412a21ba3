"""What a recorded session's messages must hold to be replayed, and how what they hold wrong is said: at the bag, the
topic and the message's stamp (``run.mcap: /joint_states at t=5.000 s (stamp 1700000005.000000000): position of
'j2' is NaN: ...``), before anything is simulated.

A number that is not finite (NaN, ±inf) in a joint's position, the person's wrench or a target is refused
(:class:`BagError`): the replay would simulate it. One in a joint state's velocity or effort is said (a
:class:`Remark`): those are left out, as where the messages have none.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError


@dataclass(frozen=True)
class Where:
    """A message of a bag: its ``topic``, its time in the session ``t_s`` [s from the first joint state] and its
    stamp [ns, Unix epoch]."""

    topic: str
    t_s: float
    stamp_ns: int

    def __str__(self) -> str:
        sec, nsec = divmod(int(self.stamp_ns), 1_000_000_000)
        return f"{self.topic} at t={self.t_s:.3f} s (stamp {sec}.{nsec:09d})"


class BagError(ScenarioError):
    """A bag that can't be replayed as asked: the ``bag``, the topic ``role`` concerned ('' for the whole bag), what
    is wrong with the fix (``what``), and — for a message's content — the message (``where``) and its ``field``
    (e.g. ``position[j2]``, ``wrench.force.z``). Said at the bag: at the message, else naming the ``--topics`` role."""

    def __init__(self, bag: Path | str, role: str, what: str, more: list[tuple[str, str]] = (),
                 where: Where | None = None, field: str | None = None):
        self.bag, self.role, self.what, self.where, self.field = str(bag), role, what, where, field
        self.problems = [(role, what), *more]  # every role's, said at once
        at = [str(where) if where is not None else (f"--topics {role}" if role else "")]
        at += [f"--topics {r}" if r else "" for r, _ in more]
        super().__init__([Diagnostic(Mark(str(bag), 0, 0), a, w) for a, (_, w) in zip(at, self.problems,
                                                                                        strict=True)])

    @property
    def located(self) -> str:
        """Where, said without the bag: the message (or the ``--topics`` role) and what."""
        return str(self.diagnostics[0]).removeprefix(f"{self.bag}: ")


@dataclass(frozen=True)
class Remark:
    """Something of the bag the replay does without, said before it runs: where, what and what is done instead."""

    bag: str
    where: Where | str
    what: str

    def __str__(self) -> str:
        return f"{self.bag}: {self.where}: {self.what}"


def not_finite(v: float) -> str:
    """How a non-finite number is said: ``NaN``, ``inf`` or ``-inf``."""
    return "NaN" if np.isnan(v) else ("inf" if v > 0 else "-inf")


def first_bad(values: np.ndarray) -> int | None:
    """The index of the first row of ``values`` (n, m) with a number that is not finite, or None."""
    bad = ~np.isfinite(values).all(axis=1)
    return int(np.argmax(bad)) if bad.any() else None


REPLAY_NEEDS = {
    "joint_states": "a replay needs every joint's position in every message: drop that message (a stretch without "
                    "messages is bridged by interpolation) or mend the value",
    "wrench": "the person's wrench would be simulated as it is: drop that message (a stretch without messages is "
              "bridged by interpolation, up to the recorded-wrench patient's max_gap_s) or mend the value",
    "targets": "a target must be a place or a posture the robot can be sent to: drop that message or mend it",
}


def refuse_rows(bag: Path, role: str, values: np.ndarray, wheres: Sequence[Where], fields: list[str],
                words: list[str] | None = None) -> None:
    """Refuse the first message whose ``values`` row holds a number that is not finite, at its column's field
    (``fields``, e.g. ``position[j2]``), said in its ``words`` (default: the field); ``wheres[i]``: row ``i``'s message
    (only the refused one's is asked for)."""
    row = first_bad(values)
    if row is None:
        return
    col = int(np.argmax(~np.isfinite(values[row])))
    said = (words or fields)[col]
    raise BagError(bag, role, f"{said} is {not_finite(values[row, col])}: {REPLAY_NEEDS[role]}", where=wheres[row],
                   field=fields[col])
