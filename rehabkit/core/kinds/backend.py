"""The backend plugin kind: its stepping core, the faults it reports, and the scene types it draws with."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rehabkit.core.kinds.metric import Metric
from rehabkit.core.kinds.run_state import RunState
from rehabkit.core.kinds.trace import Trace


@dataclass
class Contact:
    """A contact between the robot (or an object) and something else."""

    geom1: str
    geom2: str
    position: np.ndarray
    depth: float


@dataclass(frozen=True)
class GeomVisual:
    """A primitive shape fixed to a body, for drawing.

    Attributes:
        body: Body name (its pose comes from :meth:`Backend.body_poses`).
        name: Geom name.
        shape: ``box`` (half-extents), ``sphere`` (radius), ``capsule``/``cylinder``
            (radius, half-length along local z), ``plane`` (half-sizes x, y), ``mesh`` (see ``mesh``).
        size: Shape parameters [m].
        position: Offset in the body frame [m].
        quat_wxyz: Orientation in the body frame.
        rgba: Colour, 0..1.
    """

    body: str
    name: str
    shape: str
    size: tuple[float, ...]
    position: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    rgba: tuple[float, float, float, float]
    mesh: tuple[np.ndarray, np.ndarray] | None = None  # a mesh's vertices (n, 3) [m] and triangles (k, 3)


@dataclass
class Drawing:
    """Shapes that change during a run (world frame), drawn at the log rate: polylines and arrows.

    Attributes:
        lines: Polylines, each (k, 3) [m].
        line_rgba: One colour per polyline (n, 4), 0..1.
        origins: Arrow tails (m, 3) [m].
        vectors: Arrows (m, 3) [m].
        arrow_rgba: One colour per arrow (m, 4), 0..1.
        arrow_labels: A label per arrow, shown beside it (say the scale: "12.3 N (1 cm per N)").
    """

    lines: list[np.ndarray] | None = None
    line_rgba: np.ndarray | None = None
    origins: np.ndarray | None = None
    vectors: np.ndarray | None = None
    arrow_rgba: np.ndarray | None = None
    arrow_labels: list[str] | None = None


@dataclass
class BodyPoses:
    """World poses of the drawn bodies: names, positions (n, 3), quaternions (n, 4) w-x-y-z."""

    names: list[str]
    positions: np.ndarray
    quats_wxyz: np.ndarray


class BackendFaultError(RuntimeError):
    """The backend can no longer drive the robot (e.g. its link is lost); the run stops with this reason.
    ``observable``: the robot side holds it and still reports its state, so the run watches it come to rest (the
    safety stop's ``stop_after_s``) before ending. ``breach``: the joint limit the robot side saw broken, where that
    is why (a :class:`~rehabkit.core.setup.limits.LimitBreach`: its joint, value and limit become the event's).
    ``cause_code``: why, as a code (``bridge-hold``, ``state-timeout``, ``tick-unanswered``, ...), or None; the safety
    event's ``data["cause"]``, so a reader tells the causes apart without parsing the message."""

    observable = False
    breach = None
    cause_code: str | None = None

    def event_data(self) -> dict | None:
        """The fault's fields for its safety event's ``data`` (``cause``: its ``cause_code``), or None without any."""
        return {"cause": self.cause_code} if self.cause_code is not None else None


class EStopLatchedError(BackendFaultError):
    """No session starts: the robot's e-stop is latched (ISO 13850). ``latch`` names it as ``rehabkit estop clear``
    takes it; ``where`` is the robot (simulated, or behind a bridge); ``clear_right``, behind a bridge, who may clear
    it as the bridge declares ("link": any session, "key": a session under its clearing key, "keypad": its keypad
    only; None: this machine's ``rehabkit estop clear``); the message says how to clear it."""

    def __init__(self, message: str, latch: str, where: str, clear_right: str | None = None):
        super().__init__(message)
        self.latch, self.where, self.clear_right = latch, where, clear_right


class NotRestorableError(TypeError):
    """A run on this backend can't be snapshotted or restored: its state is a real robot's (a link, a bus)."""

    def __init__(self, backend: str):
        super().__init__(f"backend '{backend}' drives a robot: its state can't be taken and put back (a snapshot, a "
                         "learning environment's fast reset and a forked replay need a simulation)")
        self.backend = backend


class Backend(RunState, ABC):
    """Where commands go and state comes from: a simulator or a robot link.

    This is the stepping core every backend has. What only some backends can do — contacts, a scene to draw,
    objects, cameras, instruments, a floating base, joints by name, external torques — are the protocols of
    :mod:`rehabkit.core.kinds.capabilities` a backend derives from; plugins needing one list it in ``requires``.
    """

    timestep: float
    metrics: ClassVar[tuple[Metric, ...]] = ()  # descriptions of what run_metrics reports
    realtime: bool = False  # steps in wall-clock time (a robot link): the loop must never wait on slow work
    real_person: ClassVar[bool] = False  # drives a real robot (or its stand-in over a link): its person is real
    # its robot's e-stop latch (rehabkit.core.safety.estop) on this machine, named from the robot's name and the
    # backend's settings (``"{robot}-{robot_id}"``); None: it keeps none here
    latch_name: ClassVar[str | None] = None
    ramp_in_after_clear: float = 0.0  # set by reset: the first session after an e-stop was cleared ramps in this long
    # how long after the control period a torque takes to act on the robot, from the state it was computed at [s]: a
    # bus whose drives take their targets at the next SYNC adds one period (the safety layer's gains allow for it)
    loop_delay: float = 0.0
    # its whole state can be taken and put back (a simulation: run_state/restore_run_state); a robot's can't, and a
    # session snapshot on it is refused by this flag (NotRestorableError)
    restorable: ClassVar[bool] = False

    @abstractmethod
    def reset(self, q0: np.ndarray) -> None:
        """Put the robot at rest at ``q0``."""

    @abstractmethod
    def state(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Time [s], joint positions, joint velocities. Arrays may be views: copy to keep."""

    @abstractmethod
    def command(self, tau: np.ndarray) -> None:
        """Set joint torques for the next steps (already checked by the safety layer)."""

    @abstractmethod
    def step(self, n: int = 1) -> None:
        """Advance ``n`` timesteps."""

    def run_state(self) -> object:
        """The simulation's whole state (the scene's and the backend's own), where ``restorable``; a robot's backend
        raises :class:`NotRestorableError`."""
        if not self.restorable:
            raise NotRestorableError(type(self).__name__)
        return super().run_state()

    def run_metrics(self, trace: Trace) -> dict[str, float]:
        """Figures about the run only the backend knows (e.g. a link's deadline misses); default none."""
        return {}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Time series only the backend knows, name → (times [s], values), for the log; default none."""
        return {}

    def engage_brakes(self) -> bool:
        """Apply the robot's holding brakes (the torque has gone off: a stop of category 0 or 1); False where the
        robot has none (the default)."""
        return False

    def latch_estop(self, reason: str) -> bool:
        """Latch an e-stop at the robot: it holds across sessions until a person clears it
        (:mod:`rehabkit.core.safety.estop`), and the next session's reset is refused meanwhile. False where this backend
        keeps no latch (the default)."""
        return False

    def latched_estop(self) -> str | None:
        """The name of this robot's e-stop latch if it is latched now (as ``rehabkit estop clear`` takes it), else
        None (also the default: no latch kept)."""
        return None

    def interventions(self) -> list:
        """Safety events the robot side took on its own (``SafetyEvent``s, e.g. a hold through a gap in the
        commands); default none."""
        return []

    @classmethod
    def timestep_for(cls, config: object, control_dt: float) -> float:
        """The step the backend will take for ``config`` at a control period of ``control_dt`` (``validate``'s
        question, before it is built): its ``timestep`` setting by default."""
        return config.timestep

    @classmethod  # noqa: B027 (optional: most backends have nothing to check)
    def check(cls, config: object, context: object) -> list[str] | None:
        """Refuse, before anything runs (``rehabkit validate``), the settings known wrong without building the
        backend — a file it needs, say — as building it would: a ``SettingError`` names the setting. Returns what
        ``validate`` should say without refusing (a bus nearly full), if anything."""

    def provenance(self) -> dict[str, str]:
        """Who the commands went to and how, for the safety log's run record (a robot link: its address, whether
        its session was authenticated and under which key id; never a secret); default nothing to add."""
        return {}

    def outputs(self) -> dict[str, str]:
        """Files the backend writes into the run's folder, by what each is (a CAN trace: ``{"can_trace":
        "can.asc"}``), named in ``summary.json`` and the run's "wrote" line; default none."""
        return {}

    def close(self) -> None:  # noqa: B027 (optional hook: most backends hold nothing to release)
        """Release resources."""
