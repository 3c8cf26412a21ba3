"""Whether the robot, posed at joint values, touches the scenario's world: MuJoCo's own collision detection on a
private copy of the scene the backend simulates (same robot MJCF, same floor and obstacles).

Planners check their states and paths with it, so "collision-free" means what the simulation will find: the true
geometry of every link against every obstacle, not a voxel or sphere stand-in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rehabkit.models.robot_model import RobotModel


@dataclass(frozen=True)
class Hit:
    """A robot geom nearer than the clearance to a world geom (``distance`` < 0: they overlap) [m]."""

    robot_geom: str
    world_geom: str
    distance: float


class SceneCollision:
    """The robot against the world's fixed geometry (floor, obstacles, free objects where they start).

    ``clearance_m`` widens every world geom: a state nearer than that to an obstacle counts as a collision.
    Self-collision is not checked (the backend does not simulate it: generated links overlap at the joints).
    """

    def __init__(self, robot: RobotModel, world, clearance_m: float = 0.0):
        import mujoco

        from rehabkit.sim.scene import build_scene

        self._mj = mujoco
        spec = build_scene(robot, world, 0.002)
        root = spec.worldbody.first_body().name
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.qpos = np.array([m.jnt_qposadr[m.joint(n).id] for n in robot.joint_names])
        root_id = m.body(root).id
        robot_body = np.array([m.body_rootid[b] == root_id for b in range(m.nbody)])
        self.robot_geom = robot_body[m.geom_bodyid]
        self.clearance = float(clearance_m)
        m.geom_margin[~self.robot_geom] = self.clearance  # a pair's margin is the larger of its geoms'
        self.checks = 0

    def hits(self, q: np.ndarray) -> list[Hit]:
        """Robot–world geom pairs nearer than the clearance at joint values ``q``."""
        if not self._collide(q):
            return []
        d = self.data
        out = []
        for c in d.contact[: d.ncon]:
            g1, g2 = int(c.geom[0]), int(c.geom[1])
            if self.robot_geom[g1] != self.robot_geom[g2] and c.dist < self.clearance:
                r, w = (g1, g2) if self.robot_geom[g1] else (g2, g1)
                out.append(Hit(self._name(r), self._name(w), float(c.dist)))
        return out

    def _name(self, geom: int) -> str:
        """A geom's name, or its body's for an unnamed one (most model files name bodies, not geoms)."""
        m = self.model
        return m.geom(geom).name or f"{m.body(int(m.geom_bodyid[geom])).name or 'world'} (geom {geom})"

    def free(self, q: np.ndarray) -> bool:
        """No robot geom nearer than the clearance to the world at ``q``."""
        if not self._collide(q):
            return True
        d = self.data
        n = d.ncon
        geoms = d.contact.geom[:n]
        across = self.robot_geom[geoms[:, 0]] != self.robot_geom[geoms[:, 1]]
        return not np.any(across & (d.contact.dist[:n] < self.clearance))

    def first_collision(self, qs: np.ndarray) -> int:
        """Index of the first row of ``qs`` in collision, or -1 when all are free."""
        for i, q in enumerate(np.atleast_2d(qs)):
            if not self.free(q):
                return i
        return -1

    def _collide(self, q) -> bool:
        """Pose the robot and run MuJoCo's collision detection; whether any contact was found at all."""
        mj, m, d = self._mj, self.model, self.data
        d.qpos[self.qpos] = q
        mj.mj_kinematics(m, d)
        mj.mj_collision(m, d)
        self.checks += 1
        return d.ncon > 0
