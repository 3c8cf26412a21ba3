"""The scene of a robot driven over the link, mirrored on the host from the measured joints: drawn in the log,
its scripted objects moved there (by the scenario's events, as a therapist moves the real ones), its cameras
rendered (by a process of their own) from it."""

from __future__ import annotations

import threading

import mujoco
import numpy as np

from rehabkit.core.kinds.capabilities import Cameras, NamedJoints, SceneGeometry, SceneObjects
from rehabkit.core.kinds.interfaces import BodyPoses, GeomVisual
from rehabkit.core.scenario.models import World
from rehabkit.hardware.frame_server import FrameServer
from rehabkit.models.robot_model import RobotModel
from rehabkit.sim.scene import build_scene
from rehabkit.sim.scene_view import SceneView, measured_joints


class SceneMirror(SceneView):
    """The scenario's scene posed from measured joints (no physics): a hardware run's view of its robot.

    Two copies of the scene's data: the control thread poses and reads one (log, end
    effector); a sensor thread poses the other at the newest state when it starts a frame
    (whose pixels the frame server renders), so a slow frame never holds up the loop nor
    sees a half-updated pose.
    """

    def __init__(self, robot: RobotModel, world: World | None):
        spec = build_scene(robot, world or World(), 0.001)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.frame_data = mujoco.MjData(self.model)
        self._init_view(robot.ee_site)
        self._q = np.array([self.model.jnt_qposadr[self.model.joint(n).id] for n in robot.joint_names], int)
        self._m = measured_joints(self.model, robot)
        self.measured_count = len(self._m)
        self._lock = threading.Lock()  # scripted object moves vs a frame copying them
        self.frame_view = _FrameView(self)  # read it after frame(): what the frame showed

    def pose(self, q: np.ndarray, measured: np.ndarray) -> None:
        """Put the mirror at the measured joints (control thread)."""
        self.data.qpos[self._q] = q
        self.data.qpos[self._m] = measured
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def move_object(self, name: str, position: np.ndarray) -> None:
        with self._lock:
            super().move_object(name, position)
            mujoco.mj_kinematics(self.model, self.data)

    def frame(self, q: np.ndarray, measured: np.ndarray) -> SceneView:
        """The frame copy, posed at ``q`` with the objects where they are now (any thread)."""
        f = self.frame_data
        with self._lock:
            f.mocap_pos[:], f.mocap_quat[:] = self.data.mocap_pos, self.data.mocap_quat
        f.qpos[self._q] = q
        f.qpos[self._m] = measured
        mujoco.mj_kinematics(self.model, f)
        mujoco.mj_camlight(self.model, f)
        return self.frame_view


class _FrameView(SceneView):
    """The mirror's frame copy as a view (its own renderers)."""

    def __init__(self, mirror: SceneMirror):
        self.model, self.data = mirror.model, mirror.frame_data
        self._init_view(mirror.model.site(mirror._ee_site).name)


class MirroredScene(SceneGeometry, SceneObjects, Cameras, NamedJoints):
    """The scene capabilities of a backend that keeps ``mirror`` posed at its newest ``q`` and ``measured`` joints
    (``_posed`` false when they change) and, given cameras, a ``frames`` server."""

    mirror: SceneMirror
    frames: FrameServer | None
    q: np.ndarray
    measured: np.ndarray
    _posed: bool

    def _view(self) -> SceneView:
        if not self._posed:
            self.mirror.pose(self.q, self.measured)
            self._posed = True
        return self.mirror

    def body_poses(self) -> BodyPoses:
        return self._view().body_poses()

    def visual_geoms(self) -> list[GeomVisual]:
        return self.mirror.visual_geoms()

    def ee_position(self) -> np.ndarray:
        return self._view().ee_position()

    def joint_positions(self, names: list[str]) -> np.ndarray:
        return self._view().joint_positions(names)

    def set_joints(self, values: dict[str, np.ndarray]) -> None:
        """The mechanism assembles itself (its passive joints are measured): nothing to send."""

    def move_object(self, name: str, position: np.ndarray) -> None:
        self.mirror.move_object(name, position)

    def object_position(self, name: str) -> np.ndarray:
        """Where a scene object is in the frame last rendered (a sensor thread's question)."""
        return self.mirror.frame_view.object_position(name)

    def render(self, camera: str, width: int, height: int) -> np.ndarray:
        """A frame of the mirrored scene at the newest measured state (from a sensor thread; another process
        renders it)."""
        if self.frames is None:
            raise RuntimeError("this hardware backend renders no frames (the scenario has no cameras)")
        view = self.mirror.frame(self.q, self.measured)
        return self.frames.render(view.data, camera, width, height)

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray, float]:
        return self.mirror.frame_view.camera_pose(camera)
