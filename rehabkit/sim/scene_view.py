"""What sensors, scripted worlds and the log read from a compiled MuJoCo scene.

:class:`SceneView` holds those read-outs for any ``(model, data)`` pair: the simulation
backend is one; the hardware layer's scene mirror (:mod:`rehabkit.hardware.mirrored_scene`)
is another, the scenario's scene on the host of a hardware run, posed from the robot's
measured joints.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rehabkit.core.kinds.interfaces import BodyPoses, GeomVisual
from rehabkit.models.robot_model import RobotModel

_GEOM_SHAPES = {  # int keys: model arrays hold numpy ints, which don't hash-match the enum
    int(mujoco.mjtGeom.mjGEOM_BOX): "box", int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule", int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_PLANE): "plane", int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
}
_QPOS_SIZE = {int(mujoco.mjtJoint.mjJNT_HINGE): 1, int(mujoco.mjtJoint.mjJNT_SLIDE): 1,
              int(mujoco.mjtJoint.mjJNT_BALL): 4}  # a free joint is a floating base, not a measured joint


def measured_joints(model: mujoco.MjModel, robot: RobotModel) -> np.ndarray:
    """``qpos`` addresses of the robot's passive joints (measured, not driven; sent over a link), in its order."""
    out = []
    for name in robot.passive_joints:
        j = model.joint(name).id
        size = _QPOS_SIZE.get(int(model.jnt_type[j]), 0)
        out.extend(range(model.jnt_qposadr[j], model.jnt_qposadr[j] + size))
    return np.array(out, int)


def camera_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """An offscreen renderer for a simulated camera's frames, for colour detection: no shadows, reflections or
    multisampling, which a detector needs none of and which cost most of a frame rendered in software (640x480
    here: 38 ms with them, 13 ms without shadows and reflections, 5.6 ms without multisampling too; mean pixel
    difference of the last 0.07 of 255)."""
    samples, model.vis.quality.offsamples = model.vis.quality.offsamples, 0  # read when the context is made
    try:
        renderer = mujoco.Renderer(model, height, width)
    finally:
        model.vis.quality.offsamples = samples
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    return renderer


class SceneView:
    """Read-outs of ``self.model`` / ``self.data`` (set by the subclass before :meth:`_init_view`)."""

    model: mujoco.MjModel
    data: mujoco.MjData

    def _init_view(self, ee_site: str) -> None:
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._ee_site = self.model.site(ee_site).id
        self._drawn_names = [self.model.body(b).name for b in range(1, self.model.nbody)]  # (every body but the world)
        self._body_ids: dict[str, int] = {}  # model.body(name) makes a named view each call (~2 us)

    def ee_position(self) -> np.ndarray:
        return self.data.site_xpos[self._ee_site].copy()

    def set_joints(self, values: dict[str, np.ndarray]) -> None:
        for name, value in values.items():
            adr = self.model.jnt_qposadr[self.model.joint(name).id]
            value = np.atleast_1d(value)
            self.data.qpos[adr : adr + len(value)] = value
        mujoco.mj_forward(self.model, self.data)

    def joint_positions(self, names: list[str]) -> np.ndarray:
        adr = [self.model.jnt_qposadr[self.model.joint(n).id] for n in names]
        return self.data.qpos[adr].copy()

    def move_object(self, name: str, position: np.ndarray) -> None:
        body = self.model.body(name)
        if body.mocapid[0] < 0:
            raise ValueError(f"object '{name}' is not kinematic; set mocap: true on it to move it by events")
        self.data.mocap_pos[body.mocapid[0]] = position

    def object_position(self, name: str) -> np.ndarray:
        body = self._body_ids.get(name)
        if body is None:
            body = self._body_ids[name] = self.model.body(name).id
        return self.data.xpos[body].copy()

    def render(self, camera: str, width: int, height: int) -> np.ndarray:
        key = (width, height)
        if self._renderers.get(key) is None:
            try:
                self._renderers[key] = camera_renderer(self.model, width, height)
            except mujoco.FatalError as exc:  # typically: MuJoCo chose GLFW and there is no display
                raise RuntimeError(
                    f"cannot render camera '{camera}' offscreen ({exc}); without a display set MUJOCO_GL=egl "
                    "before MuJoCo is first imported (rehabkit does this itself when it is imported first)"
                ) from None
        renderer = self._renderers[key]
        renderer.update_scene(self.data, camera=camera)
        return renderer.render()

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray, float]:
        cid = self.model.camera(camera).id
        mj_rot = self.data.cam_xmat[cid].reshape(3, 3)
        # MuJoCo cameras look along -z with +y up; OpenCV's look along +z with +y down
        return self.data.cam_xpos[cid].copy(), mj_rot @ np.diag([1.0, -1.0, -1.0]), np.radians(self.model.cam_fovy[cid])

    def body_poses(self) -> BodyPoses:
        d = self.data  # (every body but the world: a slice copied, ~3x cheaper than taking them by index)
        return BodyPoses(self._drawn_names, d.xpos[1:].copy(), d.xquat[1:].copy())

    def visual_geoms(self) -> list[GeomVisual]:
        m = self.model
        out = []
        for g in range(m.ngeom):
            if m.geom_group[g] >= 3 or m.geom_rgba[g, 3] == 0:  # hidden, as MuJoCo's own viewer hides them
                continue
            mesh = None
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
                k = m.geom_dataid[g]
                v, f = m.mesh_vertadr[k], m.mesh_faceadr[k]
                shape, mesh = "mesh", (m.mesh_vert[v : v + m.mesh_vertnum[k]].copy(),
                                       m.mesh_face[f : f + m.mesh_facenum[k]].copy())
            else:
                shape = _GEOM_SHAPES.get(int(m.geom_type[g]))
            if shape is None:
                continue
            size = m.geom_size[g]
            size = {"box": size[:3], "sphere": size[:1], "plane": size[:2], "ellipsoid": size[:3],
                    "mesh": size[:0]}.get(shape, size[:2])
            out.append(GeomVisual(
                body=m.body(m.geom_bodyid[g]).name or "world", name=m.geom(g).name or f"geom{g}", shape=shape,
                size=tuple(float(s) for s in size), position=tuple(m.geom_pos[g]), quat_wxyz=tuple(m.geom_quat[g]),
                rgba=tuple(float(c) for c in m.geom_rgba[g]), mesh=mesh,
            ))
        return out

    def close_view(self) -> None:
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()
