"""What a metric is: its unit, whether it is reproducible, how a run's plans combine into it.

Every metric a run reports is described once, where it is produced: the core's
own below, a plugin's in its class's ``metrics`` attribute, an extension's from
its ``rehabkit_metrics`` hook. ``summary.json`` carries the description of each
metric it holds (``metric_info``), so a sweep knows which columns are wall-clock
figures (left out when runs are compared) and ``rehabkit replay`` which ones are
outcome measures, without lists of names of their own.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

Clock = Literal["sim", "wall"]
Combine = Literal["max", "min", "last", "sum"]


@dataclass(frozen=True)
class Metric:
    """The description of one metric, or of a family of them.

    Attributes:
        name: The metric's name, or a family's pattern with one ``*`` (``rom_deg_*``, ``*_ms``).
        unit: Its unit (``deg``, ``m``, ``s``, ``1`` for ratios and counts).
        clock: ``sim``: the same seed gives the same value; ``wall``: it depends on the machine's time.
        combine: How a value reported by each plan (a planner's diagnostics) becomes the run's.
        outcome: A movement or interaction outcome, compared side by side by ``rehabkit replay``.
        description: One line for people.
    """

    name: str
    unit: str = "1"
    clock: Clock = "sim"
    combine: Combine = "max"
    outcome: bool = False
    description: str = ""

    def info(self) -> dict:
        """The description as ``summary.json`` holds it (without the name)."""
        # (its fields are plain values: no dataclasses.asdict, which deep-copies each, ~5 µs a metric, ~200 a run)
        return {"unit": self.unit, "clock": self.clock, "combine": self.combine, "outcome": self.outcome,
                "description": self.description}


def combine(rule: Combine, old: float | None, new: float) -> float:
    """A plan's value merged into the run's so far by ``rule``."""
    if old is None or rule == "last":
        return new
    return {"max": max, "min": min, "sum": lambda a, b: a + b}[rule](old, new)


class MetricCatalogue:
    """Metric descriptions by name; families match by pattern. A metric nobody described gets the defaults
    (reproducible, plans combined by their maximum: residual-like figures keep the worst)."""

    def __init__(self, metrics: Iterable[Metric] = ()):
        self._exact: dict[str, Metric] = {}
        self._families: list[Metric] = []
        self.add(metrics)

    def add(self, metrics: Iterable[Metric]) -> None:
        for m in metrics:
            if "*" in m.name:
                self._families.append(m)
                self._families.sort(key=lambda f: -len(f.name))  # the longest prefix wins
            else:
                self._exact[m.name] = m

    def known(self, name: str) -> bool:
        """Whether someone described ``name`` (or a family it belongs to)."""
        return self._described(name) is not None

    def names(self) -> list[str]:
        """The described names and family patterns (for suggestions)."""
        return sorted([*self._exact, *(f.name for f in self._families)])

    def get(self, name: str) -> Metric:
        return self._described(name) or Metric(name)

    def _described(self, name: str) -> Metric | None:
        """Its description, or its family's (``*`` may stand for nothing: ``accel_filter_gain*``)."""
        if name in self._exact:
            return self._exact[name]
        for fam in self._families:
            head, _, tail = fam.name.partition("*")
            if name.startswith(head) and name.endswith(tail) and len(name) >= len(head) + len(tail):
                return fam
        return None

    def info(self, names: Iterable[str]) -> dict[str, dict]:
        """``{name: description}`` for ``names``, as ``summary.json`` keeps it."""
        return {n: self.get(n).info() for n in names}


def wall_clock(metric_info: dict[str, dict]) -> set[str]:
    """Names of the wall-clock metrics in a summary's ``metric_info``."""
    return {n for n, i in metric_info.items() if i.get("clock") == "wall"}


CORE_METRICS: tuple[Metric, ...] = (
    Metric("tracking_max_deg", "deg", description="largest joint tracking error"),
    Metric("max_velocity_ratio", description="largest |joint speed| / speed limit"),
    Metric("max_torque_ratio", description="largest |torque| / effort limit"),
    Metric("joint_limit_excess_deg", "deg", description="largest excursion beyond a revolute joint's range"),
    Metric("joint_limit_excess_m", "m", description="largest excursion beyond a prismatic joint's range"),
    Metric("final_joint_error_deg", "deg", description="last posture against the last plan's goal (revolute joints)"),
    Metric("final_joint_error_m", "m", description="the same for prismatic joints"),
    Metric("tracking_max_m", "m", description="largest tracking error of a prismatic joint"),
    Metric("final_position_error_m", "m", description="hand at the end against the goal"),
    Metric("cartesian_tracking_rms_mm", "mm", outcome=True, description="RMS of the hand's Cartesian error"),
    Metric("cartesian_tracking_max_mm", "mm", description="largest Cartesian error"),
    Metric("tracking_rms_deg", "deg", outcome=True, description="RMS of the plan's joint reference minus measured "
           "(where the controller makes the joint reference — Cartesian references, an HMI — its own)"),
    Metric("controller_tracking_rms_deg", "deg", description="RMS of the controller's own joint reference minus "
           "measured, where a joint-space controller exposes one (a compliant controller's yielded reference)"),
    Metric("controller_tracking_max_deg", "deg", description="largest of the same (revolute joints)"),
    Metric("controller_tracking_max_m", "m", description="the same for prismatic joints"),
    Metric("sim_time_s", "s", description="simulated time run"),
    Metric("task_complete", "1", description="1 when the run lasted until its last plan's end, or every reach "
           "got to its target and stayed, else 0: an unfinished task fails the run unless the scenario's "
           "expectations name task_complete or safety_events"),
    Metric("plan_end_s", "s", description="when the run's last plan ends (its start plus its duration)"),
    Metric("wall_time_s", "s", "wall", description="wall time of the loop"),
    Metric("setup_time_s", "s", "wall", description="wall time from loading to the first step"),
    Metric("real_time_factor", "1", "wall", description="simulated time / wall time of the loop"),
    Metric("contact_steps", "count", description="control steps with a robot collision"),
    Metric("safety_events", "count", description="safety trips"),
    Metric("torque_saturation_steps", "count", description="control steps with a torque clipped"),
    Metric("stop_category", "count", description="the safety stop's category (IEC 60204-1: 0, 1, 2; NaN: a "
           "force-limiting reaction that did not end in a stop)"),
    Metric("force_after_trip_peak_n", "N", description="the largest interaction force from the first trip on"),
    Metric("force_above_limit_s", "s", description="time the interaction force spent above its limit after the "
           "first trip"),
    Metric("joints_in_range", "1", description="1 when every joint stayed in its range (the run's, without the "
           "trip margin) after the first trip, else 0"),
    Metric("stop_time_s", "s", description="from the trip to standstill (every revolute joint < 1°/s and every "
           "prismatic one < 1 mm/s for 50 ms; NaN: not at rest by the run's end)"),
    Metric("stop_distance_deg", "deg", description="the largest revolute joint's travel from the trip to standstill"),
    Metric("stop_distance_m", "m", description="the hand's path from the trip to standstill"),
    Metric("stop_peak_speed_deg_s", "deg/s", description="the fastest revolute joint's speed after the trip"),
    Metric("stop_joint_travel_m", "m", description="the largest prismatic joint's travel from the trip to "
           "standstill"),
    Metric("stop_joint_peak_speed_m_s", "m/s", description="the fastest prismatic joint's speed after the trip"),
    Metric("sensor_overruns_*", "count", clock="wall", description="readings skipped while a sensor thread was busy"),
    Metric("*_ms", "ms", "wall", description="timings"),
)
