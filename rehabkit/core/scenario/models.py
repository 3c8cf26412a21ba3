"""The scenario DSL as pydantic models.

The plugin sections (``robot``, ``backend``, ``planner``, ``controller``,
``sensors``) are unions of the installed plugins' config models, discriminated
by ``type``; :func:`scenario_model` builds them from the registry after plugins
load. Angles in the DSL carry a ``_deg`` suffix; everything else is SI.
"""

# (no `from __future__ import annotations`: pydantic would evaluate each field's annotation from its text, as
# each model and every subclass is built, ~1 ms a module; a model's own name in a method's is quoted)
import math
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import ConfigDict, Field, create_model, model_validator

from rehabkit.core.kinds.interfaces import StrictModel
from rehabkit.core.plugins.lifecycle import Extensions, default_extensions
from rehabkit.core.plugins.registry import PluginRegistry
from rehabkit.core.scenario.loads import Load
from rehabkit.core.scenario.safety import SafetyConfig

Vec3 = tuple[float, float, float]


class Pose(StrictModel):
    """A pose: position [m] and fixed-axis roll-pitch-yaw [deg]."""

    position: Vec3 = (0.0, 0.0, 0.0)
    rpy_deg: Vec3 = (0.0, 0.0, 0.0)


_SIZES = {"box": ("half-extents x, y, z", 3), "cylinder": ("radius, half-length", 2), "sphere": ("radius", 1)}


class WorldObject(StrictModel):
    """An obstacle (static) or a free object (``dynamic: true``) in the scene."""

    name: str
    shape: Literal["box", "cylinder", "sphere"]
    size: list[Annotated[float, Field(gt=0)]] = Field(description="box: half-extents; cylinder: radius, half-length")
    pose: Pose = Pose()
    dynamic: bool = False
    mocap: bool = Field(False, description="kinematic: moved by 'move' events, pushed by nothing")
    mass: float = Field(0.1, gt=0, description="[kg], dynamic objects only")
    rgba: tuple[float, float, float, float] = (0.8, 0.3, 0.3, 0.6)
    emission: float = Field(0.0, ge=0, le=1, description="self-lit fraction of its colour (a fluorescent target)")
    held_by: str | None = Field(None, description="dynamic objects: the robot site it starts held at (a ball in a "
                                                  "hand); plans release and grasp it again")

    @model_validator(mode="after")
    def _size_matches_shape(self) -> 'WorldObject':
        what, n = _SIZES[self.shape]
        if len(self.size) != n:
            raise ValueError(f"a {self.shape} takes {n} size value(s) ({what}), got {len(self.size)}")
        if self.dynamic and self.mocap:
            raise ValueError(f"object '{self.name}': dynamic (free) and mocap (kinematic) exclude each other")
        if self.held_by is not None and not self.dynamic:
            raise ValueError(f"object '{self.name}': only a dynamic object can be held (add dynamic: true)")
        return self


class CameraSpec(StrictModel):
    """A camera in the scene (world frame), pointed at a point."""

    name: str
    position: Vec3
    look_at: Vec3
    up: Vec3 = Field((0.0, 1.0, 0.0), description="world direction that appears upward in the image")
    fovy_deg: float = Field(60.0, gt=1, lt=179, description="vertical field of view")


class World(StrictModel):
    """Everything in the scene besides the robot."""

    floor: bool = True
    objects: list[WorldObject] = []
    cameras: list[CameraSpec] = []
    loads: list[Load] = Field([], description="test-rig forces on robot bodies (a push on the handle)")

    @model_validator(mode="after")
    def _unique_names(self) -> 'World':
        names = [o.name for o in self.objects] + [c.name for c in self.cameras] + [x.name for x in self.loads]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"world object names must be unique; repeated: {dup}")
        return self


class RandomTargetSpec(StrictModel):
    """A point drawn from the robot's workspace table with the scenario's seed (one stream per target)."""

    within: Literal["workspace"] = "workspace"
    not_straight_from: str | None = Field(
        None, description="redraw until the straight segment from this target's point leaves the workspace")


class TargetSpec(StrictModel):
    """A task target: joint values, a Cartesian point (base frame), a random point, or a copy of another."""

    name: str
    joints_deg: list[float] | None = Field(None, description="a posture, every joint in degrees (a robot with a "
                                           "prismatic joint: use joints)")
    joints_rad: list[float] | None = Field(None, description="a posture in SI values: radians for revolute joints, "
                                           "metres for prismatic ones (as ROS's JointState; what a bag replays)")
    joints: list[float] | None = Field(None, description="a posture, each joint in its own unit: degrees for a "
                                       "revolute joint, metres for a prismatic one")
    position: Vec3 | None = Field(None, description="end-effector position in the robot base frame [m]")
    rpy_deg: Vec3 | None = Field(None, description="end-effector orientation; omit with orientation_of")
    orientation_of: str | None = Field(None, description="use the orientation of this (joint-space) target")
    free_axes: Literal["x", "y", "z", "xy", "xz", "yz"] | None = Field(
        None, description="tool axes the orientation may turn about: 'z' asks only that the tool's z axis point "
                          "as rpy_deg's does")
    same_as: str | None = None
    sensor: str | None = Field(None, description="position seen by this sensor (its 'target_position' reading)")
    random: RandomTargetSpec | None = Field(None, description="a random point of the workspace (seeded)")

    @model_validator(mode="after")
    def _one_kind(self) -> 'TargetSpec':
        kinds = ("joints_deg", "joints_rad", "joints", "position", "same_as", "sensor", "random")
        given = [k for k in kinds if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                f"target '{self.name}' needs exactly one of {', '.join(kinds)}; got {given or 'none'}"
            )
        if self.position is None and (self.rpy_deg is not None or self.orientation_of is not None):
            raise ValueError(f"target '{self.name}': rpy_deg/orientation_of only go with position")
        if self.free_axes is not None and self.rpy_deg is None and self.orientation_of is None:
            raise ValueError(f"target '{self.name}': free_axes goes with rpy_deg or orientation_of")
        if self.rpy_deg is not None and self.orientation_of is not None:
            raise ValueError(f"target '{self.name}': give rpy_deg or orientation_of, not both")
        return self


class EventSpec(StrictModel):
    """Something that happens during the run.

    Triggers: ``at`` a time; when a target is ``reached``; or each time a sensed
    target has ``moved`` (stable for ``settle`` readings, then fires again on the
    next move). Actions: ``replan``, ``stop``, ``move`` a mocap object, or ``estop``.
    """

    at: float | None = Field(None, ge=0, description="[s] from the start")
    reached: str | None = Field(None, description="fires when the end effector is within tolerance of this target")
    moved: str | None = Field(None, description="fires whenever this sensor-driven target moves (repeating)")
    tolerance_m: float = Field(0.005, gt=0, description="distance for 'reached' / movement for 'moved' [m]")
    settle: int = Field(3, ge=1, description="'moved': readings the new position must hold before firing")
    action: Literal["replan", "stop", "move", "estop"] = Field("replan", description="'estop': an e-stop pressed "
                                                               "(stopped in its category, latched at the robot)")
    sequence: list[str] | None = Field(None, description="replan through these targets (default: those of the plan "
                                                          "being followed not reached yet)")
    planner: dict[str, Any] | None = Field(None, description="'replan': settings of the scenario's planner for this "
                                                             "plan, over its own (e.g. segment_durations)")
    object: str | None = Field(None, description="'move': the mocap object")
    position: Vec3 | None = Field(None, description="'move': its new world position [m]")

    @model_validator(mode="after")
    def _one_trigger(self) -> 'EventSpec':
        if sum(x is not None for x in (self.at, self.reached, self.moved)) != 1:
            raise ValueError("an event needs exactly one trigger: 'at', 'reached' or 'moved'")
        if self.planner is not None and self.action != "replan":
            raise ValueError("only a 'replan' event takes planner settings")
        if (self.action == "move") != (self.object is not None and self.position is not None):
            raise ValueError("a 'move' event needs 'object' and 'position' (and only a move takes them)")
        return self


class TaskSpec(StrictModel):
    """Targets, the order to visit them, and the event timeline."""

    targets: list[TargetSpec] = Field(min_length=1)
    start: str | None = Field(None, description="joint-space target the robot starts at (default: first in sequence)")
    sequence: list[str] | None = Field(None, description="order of targets (default: as listed)")
    events: list[EventSpec] = []

    @model_validator(mode="after")
    def _names_exist(self) -> 'TaskSpec':
        names = [t.name for t in self.targets]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"target names must be unique; repeated: {dup}")
        refs = list(self.sequence or []) + ([self.start] if self.start else [])
        for t in self.targets:
            refs += [r for r in (t.same_as, t.orientation_of) if r]
        for e in self.events:
            refs += list(e.sequence or []) + [r for r in (e.reached, e.moved) if r]
        unknown = sorted(set(refs) - set(names))
        if unknown:
            raise ValueError(f"unknown target name(s) {unknown}; targets are {names}")
        return self

    def order(self) -> list[str]:
        return list(self.sequence) if self.sequence else [t.name for t in self.targets]


class Rates(StrictModel):
    """Loop rates. Physics runs at the backend's timestep."""

    control_hz: float = Field(1000.0, gt=0)


class Logging(StrictModel):
    """What the run writes besides ``summary.json``."""

    rrd: bool = True
    rate_hz: float = Field(100.0, gt=0, description="rate of 3-D poses and time series in the .rrd")
    application_id: str = "rehabkit"


class Bound(StrictModel):
    """An acceptance criterion on one metric; all given bounds must hold."""

    lt: float | None = None
    le: float | None = None
    gt: float | None = None
    ge: float | None = None
    eq: float | None = None
    tol: float = Field(1e-9, ge=0, description="tolerance for eq")

    @model_validator(mode="after")
    def _some_bound(self) -> 'Bound':
        if all(getattr(self, k) is None for k in ("lt", "le", "gt", "ge", "eq")):
            raise ValueError("give at least one of lt, le, gt, ge, eq")
        return self

    def check(self, value: float) -> bool:
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return False
        return all(
            (
                self.lt is None or value < self.lt,
                self.le is None or value <= self.le,
                self.gt is None or value > self.gt,
                self.ge is None or value >= self.ge,
                self.eq is None or abs(value - self.eq) <= self.tol,
            )
        )

    def describe(self) -> str:
        ops = {"lt": "<", "le": "<=", "gt": ">", "ge": ">=", "eq": "=="}
        return " and ".join(f"{ops[k]} {getattr(self, k)}" for k in ops if getattr(self, k) is not None)


class ScenarioBase(StrictModel):
    """The plugin-independent part of a scenario: the core's sections (the layers' own are added by
    :func:`scenario_model`, each from the extension that owns it)."""

    # never validated itself: the Scenario model scenario_model makes of it is (built when made: defer_build=False)
    model_config = ConfigDict(defer_build=True)

    name: str | None = None
    description: str | None = None
    world: World = World()
    task: TaskSpec
    duration: float = Field(gt=0, description="simulated time [s]")
    rates: Rates = Rates()
    seed: int = 0
    logging: Logging = Logging()
    safety: SafetyConfig = SafetyConfig()
    expect: dict[str, Bound] = {}


PLUGIN_SECTIONS = {"robot": "robot", "backend": "backend", "planner": "planner", "controller": "controller"}
DEFAULT_BACKEND = "mujoco"  # a scenario without a backend: section runs on this one (the DSL's one default plugin)


def plugin_union(registry: PluginRegistry, kind: str):
    """The settings models of every installed plugin of ``kind``, told apart by ``type`` (None: there is none)."""
    configs = tuple(info.config for info in registry.plugins[kind].values())
    if not configs:
        return None
    if len(configs) == 1:
        return configs[0]
    return Annotated[Union[configs], Field(discriminator="type")]  # noqa: UP007 (runtime-built union)


# the Scenario models made, by the plugins' settings models and the extensions' sections they are made of: pydantic
# takes ~5 ms to make one, and each load, validate and sweep point asked for it again
_MODELS: dict[tuple, tuple[type[ScenarioBase], dict]] = {}


def scenario_model(registry: PluginRegistry, extensions: Extensions | None = None) -> type[ScenarioBase]:
    """The full Scenario model for the installed plugins and the extensions' sections (default: the installed)."""
    sections = (extensions or default_extensions()).sections(registry)
    kinds = (*PLUGIN_SECTIONS.values(), "sensor")
    key = (tuple(tuple(info.config for info in registry.plugins[kind].values()) for kind in kinds),
           tuple((name, owner, id(section)) for name, (owner, section) in sections.items()))
    made = _MODELS.get(key)
    if made is None:
        if len(_MODELS) >= 32:
            _MODELS.clear()
        # (the sections held with it: the ids in its key stay theirs)
        made = _MODELS[key] = (_scenario_model(registry, sections), sections)
    return made[0]


def _scenario_model(registry: PluginRegistry, sections: dict) -> type[ScenarioBase]:
    fields = {}
    for section, kind in PLUGIN_SECTIONS.items():
        union = plugin_union(registry, kind)
        if union is None:
            continue
        if kind == "backend":
            fields[section] = (union, Field(default={"type": DEFAULT_BACKEND}, validate_default=True))
        else:
            fields[section] = (union, ...)
    sensor_union = plugin_union(registry, "sensor")
    # no sensor plugin loaded: the scenario names none (a named one is loaded, or refused as unknown first)
    fields["sensors"] = (dict[str, sensor_union] if sensor_union is not None else dict[str, Any], {})
    for name, (owner, section) in sections.items():
        if name in ScenarioBase.model_fields or name in fields:
            raise ValueError(f"extension '{owner}' declares the scenario section '{name}', which is the core's")
        kind = section.model if section.default is not None else Optional[section.model]  # noqa: UP045
        fields[name] = (kind, Field(section.default, description=section.description or None))
    return create_model("Scenario", __base__=ScenarioBase, __cls_kwargs__={"defer_build": False}, **fields)
