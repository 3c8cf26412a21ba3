"""The scene of a robot driven over the link, mirrored on the host from the measured joints: drawn in the log,
its scripted objects moved there, its cameras rendered (by a process of their own) from it."""

from __future__ import annotations

import numpy as np

from rehabkit.core.backends.scene_view import SceneMirror, SceneView
from rehabkit.core.capabilities import Cameras, NamedJoints, SceneGeometry, SceneObjects
from rehabkit.core.interfaces import BodyPoses, GeomVisual
from rehabkit.hardware.frame_server import FrameServer


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
