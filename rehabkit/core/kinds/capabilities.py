"""What a robot or a backend can do beyond the basics of its kind, declared, not guessed.

A robot (or backend) plugin states a capability by deriving from its protocol
(``class MyArm(Robot, WorkspaceTable)``, ``class MySim(Backend, Cameras)``) and
implementing it. A planner, controller or sensor that needs one lists it in its
class's ``requires`` attribute (``requires = (WorkspaceTable,)``); the run's setup —
and ``rehabkit validate`` — refuse a scenario whose robot or backend lacks it, by
name, before anything runs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class WorkspaceTable(Protocol):
    """A voxel look-up table of the hand's workspace (robot base frame)."""


    def workspace(self, resolution: float = 0.01, progress: bool = True, use_cache: bool = True) -> Any:
        """The table (a :class:`rehabkit.workspace.grid.VoxelWorkspace`)."""
        ...


@runtime_checkable
class RandomReach(Protocol):
    """Draws reachable hand positions at random (``task.targets[].random``)."""


    def random_reach(self, rng: np.random.Generator, not_straight_from: np.ndarray | None = None) -> np.ndarray:
        """A hand position [m] (base frame) well inside the workspace; with ``not_straight_from``, one whose
        straight line from that point leaves the workspace (a reach that needs planning around)."""
        ...


@runtime_checkable
class PassiveJoints(Protocol):
    """A mechanism with joints that follow the driven ones (a parallel robot's passive joints)."""


    def passive_state(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Every simulated joint's value (by name) for driven joint values ``q``."""
        ...


    def cluster_points(self, qs: np.ndarray) -> np.ndarray:
        """World points (n, k, 3) of the moving body at configurations ``qs`` (n, dof)."""
        ...


@runtime_checkable
class FloatingBase(Protocol):
    """A floating-base robot (a humanoid): its model seen from the world, and a standing posture."""

    standing: np.ndarray

    @property
    def floating_model(self) -> Any:
        """The Pinocchio model with the free root joint."""
        ...


# -- backends --------------------------------------------------------------------------------------------


@runtime_checkable
class Contacts(Protocol):
    """Reports the robot's contacts (collisions; a floating robot's feet on the floor excluded)."""

    def contacts(self) -> list:
        """Current contacts involving the robot (:class:`rehabkit.core.kinds.interfaces.Contact`)."""
        ...


@runtime_checkable
class SceneGeometry(Protocol):
    """A scene to draw: shapes fixed to bodies, the bodies' poses, the hand's position."""

    def visual_geoms(self) -> list:
        """Shapes to draw (:class:`rehabkit.core.kinds.interfaces.GeomVisual`), fixed to bodies."""
        ...

    def body_poses(self) -> Any:
        """World poses of the bodies that carry the shapes (:class:`rehabkit.core.kinds.interfaces.BodyPoses`)."""
        ...

    def ee_position(self) -> np.ndarray:
        """World position of the robot's end effector."""
        ...


@runtime_checkable
class SceneObjects(Protocol):
    """Objects in the scene: placed by the task (``move`` events) and their true positions."""

    def move_object(self, name: str, position: np.ndarray) -> None:
        """Put a kinematic (mocap) object at a world position."""
        ...

    def object_position(self, name: str) -> np.ndarray:
        """Ground-truth world position of a scene object."""
        ...


@runtime_checkable
class HeldObjects(Protocol):
    """Objects held by the robot (``held_by``) that plans ``grasp`` and ``release`` (its ``scene_actions``)."""

    def grasp(self, name: str) -> None:
        """Put a held object back at its holder, at rest, and hold it there."""
        ...

    def release(self, name: str) -> None:
        """Let go of a held object: from now on it moves freely."""
        ...


def scene_actions(backend: Any) -> dict[str, Callable[[str], None]]:
    """The actions a plan may schedule on this backend's scene, by name (``Plan.actions``), each the method doing
    it: ``grasp`` and ``release`` where it holds objects, none elsewhere."""
    if isinstance(backend, HeldObjects):
        return {"grasp": backend.grasp, "release": backend.release}
    return {}


@runtime_checkable
class Cameras(Protocol):
    """Renders the scene's cameras."""

    def render(self, camera: str, width: int, height: int) -> np.ndarray:
        """An RGB image (height, width, 3) uint8 from a scene camera."""
        ...

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray, float]:
        """World position, world rotation (OpenCV axes: x right, y down, z forward) and vertical FOV [rad]."""
        ...


@runtime_checkable
class Instruments(Protocol):
    """Reads the instruments sensors declare (accelerometers, gyros, force-torque sensors): simulated in its scene, or
    read by the robot side and carried over the link."""

    def read_instrument(self, name: str) -> np.ndarray:
        """The current value of an instrument a sensor asked for."""
        ...


@runtime_checkable
class BaseState(Protocol):
    """Reports a floating robot's root."""

    def base_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World position, quaternion (w, x, y, z), linear and angular velocity (world)."""
        ...


@runtime_checkable
class NamedJoints(Protocol):
    """Reads and sets joints by name, passive ones included (closing a parallel mechanism)."""

    def joint_positions(self, names: list[str]) -> np.ndarray:
        """Positions of named joints."""
        ...

    def set_joints(self, values: dict[str, np.ndarray]) -> None:
        """Set named joints."""
        ...


@runtime_checkable
class ExternalTorques(Protocol):
    """Applies joint torques from outside the robot (a simulated person's)."""

    def external_torque(self, tau: np.ndarray) -> None:
        """Torques added to the command just sent, for the next steps."""
        ...


@runtime_checkable
class HostsBodies(Protocol):
    """Simulates bodies besides the robot in its scene (an embodied patient: ``Context.bodies``)."""

    def hosted(self) -> list:
        """The bodies composed into its scene (:class:`rehabkit.core.kinds.interfaces.EmbodiedPatient`)."""
        ...


@runtime_checkable
class CompliantGaps(Protocol):
    """Drives a robot that bridges gaps in the commands on its own (a link's robot side), and can be told that the
    host's torques are a compliant reaction (a yield), so that such a gap is bridged without stiffness."""

    def comply(self, on: bool) -> None:
        """From now on, until told otherwise, the host's torques yield to the person: no stiff hold in a gap."""
        ...


@runtime_checkable
class FollowsReference(Protocol):
    """Drives joints on position or velocity targets (servo drives in cyclic synchronous position or velocity, their
    own loops closed on them) when ``follows``: each step it is given the run's joint reference as the safety layer
    lets it through (in range, within the speed limits; after a trip, the stop's ramp, then the held posture)."""

    follows: bool

    def follow(self, q: np.ndarray, qd: np.ndarray) -> None:
        """The targets for the next step: positions [rad, m] and velocities."""
        ...


ABILITY: dict[type, str] = {
    WorkspaceTable: "has a workspace look-up table (robot.workspace)",
    RandomReach: "draws random reachable targets (robot.random_reach)",
    PassiveJoints: "assembles its passive joints (robot.passive_state)",
    FloatingBase: "has a floating base (robot.floating_model, robot.standing)",
}
BACKEND_ABILITY: dict[type, str] = {
    Contacts: "reports contacts",
    SceneGeometry: "has a scene to draw",
    SceneObjects: "has scene objects to move and locate",
    HeldObjects: "grasps and releases held objects",
    Cameras: "renders cameras",
    Instruments: "reads instruments (simulated, or carried over a robot link)",
    BaseState: "reports a floating base's state",
    NamedJoints: "reads and sets joints by name",
    ExternalTorques: "applies a simulated person's torques",
    HostsBodies: "simulates a person's body in its scene",
    CompliantGaps: "bridges gaps in the commands compliantly during a yield",
}


def lacking(requires: Iterable[type], robot: Any, backend: Any = None) -> list[type]:
    """The capabilities of ``requires`` (a plugin's declaration, ``PluginInfo.declared.requires``) that ``robot``
    and ``backend`` (an instance or its class: these protocols hold methods only) lack, as the protocols."""
    out = []
    for cap in requires:
        if cap in BACKEND_ABILITY:
            if backend is None:
                continue
            if not (issubclass(backend, cap) if isinstance(backend, type) else isinstance(backend, cap)):
                out.append(cap)
        elif not isinstance(robot, cap):
            out.append(cap)
    return out


def missing_capabilities(requires: Iterable[type], robot: Any, backend: Any = None) -> list[str]:
    """What a plugin that ``requires`` these capabilities needs of ``robot`` and ``backend`` that they lack
    (:func:`lacking`), in words."""
    return in_words(lacking(requires, robot, backend))


def in_words(caps: Iterable[type]) -> list[str]:
    """Capabilities a plugin needs, each as what it needs: ``a robot that …``, ``a backend that …``."""
    return [f"a backend that {BACKEND_ABILITY[cap]}" if cap in BACKEND_ABILITY else
            f"a robot that {ABILITY.get(cap) or _ability(cap)}" for cap in caps]


def _ability(cap: type) -> str:
    """A capability declared outside the core (beside the robots that have it), in its own words: its docstring's
    first sentence, a verb phrase by convention ("Gives points on its moving body …")."""
    first = (cap.__doc__ or cap.__name__).strip().split("\n")[0].rstrip(".")
    return first[:1].lower() + first[1:]
