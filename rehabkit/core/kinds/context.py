"""What every plugin factory receives besides its own settings: the run's :class:`Context`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import ValidationError

from rehabkit.core.kinds.sensor import Instrument, Reading

ReferenceSpace = Literal["joint", "cartesian"]


class Seeds:
    """The run's random generators, each made from the scenario's seed and a key of its own (``Context.rng``: no key;
    ``Context.stream(name)``: the name's bytes). It keeps what it made so that a learning environment can start its
    next episode on another seed without building the run again: :meth:`reseed`, valid while :meth:`untouched`."""

    def __init__(self, seed: int):
        self.seed = seed
        self._made: list[tuple[tuple[int, ...], np.random.Generator]] = []

    def _fresh(self, seed: int, key: tuple[int, ...]) -> np.random.Generator:
        return np.random.default_rng([seed, *key] if key else seed)

    def generator(self, *key: int) -> np.random.Generator:
        """A generator of its own for ``key`` (none: the run's shared one)."""
        gen = self._fresh(self.seed, key)
        self._made.append((key, gen))
        return gen

    def untouched(self) -> bool:
        """No generator made has been drawn from yet: all the run did so far is the same on any seed."""
        return all(gen.bit_generator.state == self._fresh(self.seed, key).bit_generator.state
                   for key, gen in self._made)

    def reseed(self, seed: int) -> None:
        """Every generator made, as made from ``seed`` (each in place: whoever holds it draws the new stream)."""
        for key, gen in self._made:
            gen.bit_generator.state = self._fresh(seed, key).bit_generator.state
        self.seed = seed


@dataclass(frozen=True)
class Context:
    """What every plugin factory receives besides its own config (read-only: the run's setup makes a new one
    as it learns more — the robot, the sensors' instruments, the planner's space).

    Attributes:
        scenario_dir: Folder of the scenario file; relative paths resolve from here.
        rng: The run's random generator (seeded from the scenario's ``seed``).
        control_dt: Controller period [s].
        robot: The robot plugin instance, once built (robots themselves get ``None``).
        world: The scenario's world section.
        out_dir: Where the run writes its files (``None`` when it writes none).
        plan: For controllers that plan on their own (e.g. an HMI replaying a stored target):
            ``plan(t, q, qd, targets)`` asks the scenario's planner, checks, logs and returns
            the :class:`Plan`, or raises :class:`PlanningError`.
        note: ``note(t, text)`` keeps a message for people (an HMI display line) in the summary and log.
        interaction_force: ``interaction_force()``: the force between person and robot the safety envelope checked
            at the last control step [N] (a force-torque sensor's, a strapped person's, or estimated from a simulated
            person's torques), or None where the run has no source of it.
        plugins: The run's plugin registry, for :meth:`build`.
        latest: ``latest(sensor)``: the run session's latest reading of a sensor, for :meth:`reading` (None outside
            a run: what changes while a run goes is the session's, not the context's).
    """

    scenario_dir: Path
    rng: np.random.Generator
    control_dt: float
    robot: Any = None  # the robot plugin (a Robot; this module is below the kinds it is handed to)
    world: Any = None  # the scenario's world section (``rehabkit.core.scenario.models.World``)
    instruments: list[Instrument] = field(default_factory=list)
    out_dir: Path | None = None
    robot_spec: dict[str, Any] | None = None  # the scenario's robot section (type + settings), e.g. for a bridge
    plan: Callable[..., Any] | None = None  # returns a Plan
    note: Callable[[float, str], None] | None = None
    reference_space: ReferenceSpace = "joint"  # what the scenario's planner produces (controllers taking either)
    seed: int = 0
    safety: Any = None  # the scenario's safety envelope (``SafetyConfig``), e.g. for a link's heartbeat
    patient: Any = None  # the section holding the simulated patient's settings: the rehab layer's profile, if any
    dry_run: bool = False  # built to be checked, not run (``rehabkit validate``): open and write nothing
    bodies: tuple[Any, ...] = ()  # simulated bodies the backend composes into its scene (an embodied patient)
    interaction_force: Callable[[], np.ndarray | None] | None = None
    plugins: Any = None  # the run's plugin registry (``build`` makes others from it)
    latest: Callable[[str], Reading | None] | None = None  # the session's latest reading of a sensor (``reading``)
    seeds: Seeds | None = None  # what made ``rng`` and makes each ``stream``: a reset may re-seed them in place

    def reading(self, sensor: str) -> Reading | None:
        """The latest reading of the scenario's sensor named ``sensor`` (its values, time and frame), or None
        before its first. Name the sensor in a :data:`~rehabkit.models.strict.SensorName` setting: the setup then
        checks that the scenario has it, located at that setting."""
        return self.latest(sensor) if self.latest is not None else None

    def build(self, kind: str, section: dict[str, Any]) -> Any:
        """Another plugin of the run's from its section (``type`` and settings), built with this context: a
        plugin that wraps another (``policy``'s ``base`` controller). Raises ``ValueError`` saying what in the
        section is wrong (the caller names where the section is)."""
        if "type" not in section:
            raise ValueError(f"give the {kind}'s type")
        try:
            info = self.plugins.get(kind, section["type"])
        except Exception as exc:  # noqa: BLE001 (the registry's UnknownPluginError: its words, with suggestions)
            raise ValueError(str(exc)) from exc
        try:
            config = info.config.model_validate(section)
        except ValidationError as exc:
            problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or '(section)'}: {e['msg']}" for e in exc.errors())
            raise ValueError(f"{kind} '{section['type']}': {problems}") from None
        return info.factory(config, self)

    def stream(self, name: str) -> np.random.Generator:
        """A random generator of its own for ``name``, from the scenario seed.

        Draws from it don't depend on what other plugins draw, so a counterfactual replay with another
        controller sees the same patient noise and sensor noise.
        """
        if self.seeds is not None:
            return self.seeds.generator(*name.encode())
        return np.random.default_rng([self.seed, *name.encode()])

    def resolve(self, path: str | Path) -> Path:
        """A path from the scenario, made absolute relative to the scenario file."""
        p = Path(path).expanduser()
        return p if p.is_absolute() else (self.scenario_dir / p).resolve()
