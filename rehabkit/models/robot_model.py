"""The robot description every other part of rehabkit works from.

A :class:`RobotModel` is one MJCF document (the robot alone, its root body at
the origin of the robot base frame), a base pose in the world, joint limits and
an end-effector site. MuJoCo simulates that document; Pinocchio loads the *same*
file, so the controller's dynamics and the simulator's can't drift apart.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Literal

import numpy as np

from rehabkit.models.wearable import Wearable

SafeStop = Literal["hold", "zero-torque"]


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits, arrays of length ``dof``.

    Attributes:
        lower: Lowest position [rad] or [m].
        upper: Highest position [rad] or [m].
        velocity: Largest speed magnitude [rad/s] or [m/s].
        effort: Largest torque/force magnitude [N·m] or [N].
    """

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.lower)
        for name in ("upper", "velocity", "effort"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"joint limits: '{name}' has {len(getattr(self, name))} values, expected {n}")
        if np.any(self.lower >= self.upper):
            bad = [i for i in range(n) if self.lower[i] >= self.upper[i]]
            raise ValueError(f"joint limits: lower >= upper for joint index {bad}")

    def override(self, index: int, **values: float | None) -> JointLimits:
        """A copy with some limits of joint ``index`` replaced (``None`` keeps the old one)."""
        arrays = {k: getattr(self, k).copy() for k in ("lower", "upper", "velocity", "effort")}
        for key, value in values.items():
            if value is not None:
                arrays[key][index] = value
        return JointLimits(**arrays)


FRICTION_FADE_DEG_S = 1.0  # a joint's Coulomb friction, as the model gives it, fades in below this speed ...
FRICTION_FADE_M_S = 0.001  # ... (a sliding joint's): dry friction has no sign at rest


@dataclass(frozen=True)
class JointDissipation:
    """What a robot's joints lose to their own drives, as its file declares it (a URDF's ``<dynamics damping
    friction>``, an MJCF joint's ``damping`` and ``frictionloss``), per joint in the order of ``q``.

    Attributes:
        damping: Viscous damping [N·m·s/rad], or [N·s/m] for a sliding joint.
        friction: Coulomb friction [N·m], or [N].
        fade: The speed below which the friction fades in [rad/s, or m/s] (its sign is undefined at rest).
    """

    damping: np.ndarray
    friction: np.ndarray
    fade: np.ndarray

    def __post_init__(self) -> None:  # (the control loop's: a robot declaring no friction pays no tanh per step)
        object.__setattr__(self, "_dry", bool(np.any(self.friction > 0)))

    def torque(self, qd: np.ndarray) -> np.ndarray:
        """The torque the joints lose at speeds ``qd``: what a feedforward adds to move them at those speeds."""
        qd = np.asarray(qd, float)
        if not self._dry:
            return self.damping * qd
        return self.damping * qd + self.friction * np.tanh(qd / self.fade)


@dataclass
class RobotModel:
    """A robot ready to simulate and to compute with.

    Attributes:
        name: Model name.
        mjcf: MJCF XML of the robot alone; its root body is at the base frame origin.
        joint_names: Actuated joints, in the order of ``q``.
        limits: Joint limits in that order.
        ee_site: Name of the end-effector site in ``mjcf``.
        base_pose: 4x4 pose of the base frame in the world.
        safe_stop: What the safety layer does to this robot when it trips.
        gravity: World gravity [m/s^2].
        passive_joints: Joints in the MJCF that are simulated and can be measured but
            not driven (e.g. a free wrist rotation); Pinocchio's model locks them at zero.
        floating: The root body has a free joint (a humanoid): ``base_pose`` is then only
            where it starts, and Pinocchio's model (with ``root`` among the passive joints)
            is the robot seen from its root body.
        support_geoms: Geoms whose contact with the floor is support (feet), not a collision.
        wearable: Where a simulated person's arm sits in the robot and where it is strapped to it.
        brakes: Holding brakes per joint [N·m, or N], engaged when the torque goes off (safety stop categories 0
            and 1); None: no brakes.
        ee_body: The body the end-effector site was put at the origin of, when the file named a body: Pinocchio's
            frame of that body is the end effector (its parser places a site on a massless body wrongly).
    """

    name: str
    mjcf: str
    joint_names: list[str]
    limits: JointLimits
    ee_site: str
    base_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    safe_stop: SafeStop = "hold"
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    asset_dir: Path | None = None
    passive_joints: list[str] = field(default_factory=list)
    floating: bool = False
    support_geoms: list[str] = field(default_factory=list)
    wearable: Wearable | None = None  # where a person's arm sits in it (exoskeletons)
    brakes: np.ndarray | None = None
    ee_body: str | None = None

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def mjcf_pin_model(self):
        """Pinocchio's model of the MJCF as written (a floating root stays free; :attr:`pin_model` is the robot's own):
        its parser reads files only, so the MJCF is a file in the cache, named by its content (written whole: temp,
        then rename) and kept — one per robot variant however many runs, and none left half-written or behind by a
        process killed while it read (a temporary file removed after reading was, by a bridge killed mid-build). A
        robot whose mesh paths are relative to its assets (``asset_dir``) has its file beside them, removed once
        read."""
        import hashlib

        import pinocchio as pin

        if self.asset_dir is not None:
            fd, name = tempfile.mkstemp(prefix=f".rehabkit-{self.name}-", suffix=".xml", dir=self.asset_dir)
            try:
                with os.fdopen(fd, "w") as f:
                    f.write(self.mjcf)
                return pin.buildModelFromMJCF(name)
            finally:
                Path(name).unlink(missing_ok=True)
        from rehabkit.models.files.ros_package import cache_dir

        folder = cache_dir() / "mjcf"
        path = folder / f"{self.name}-{hashlib.sha256(self.mjcf.encode()).hexdigest()[:16]}.xml"
        if not path.exists():
            folder.mkdir(parents=True, exist_ok=True)
            fd, part = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=folder)
            with os.fdopen(fd, "w") as f:
                f.write(self.mjcf)
            os.replace(part, path)
        return pin.buildModelFromMJCF(str(path))

    @cached_property
    def pin_model(self):
        """Pinocchio model of the same MJCF, expressed in the robot base frame.

        Pinocchio's MJCF parser ignores the root body's placement, so the model is
        kept in the base frame and gravity is rotated into it here.
        """
        import pinocchio as pin

        model = self.mjcf_pin_model()
        if self.passive_joints:
            missing = [j for j in self.passive_joints if not model.existJointName(j)]
            if missing:
                raise ValueError(f"{self.name}: passive joint(s) {missing} are not in the model")
            coupled = self.couplings
            locked = [model.getJointId(j) for j in self.passive_joints if j not in coupled]
            if locked:
                model = pin.buildReducedModel(model, locked, pin.neutral(model))
            for follower, (leader, offset, scale) in coupled.items():
                # a joint coupled to another (a URDF's <mimic>: Panda's second finger) moves with it in the model
                # too, its mass and its drive's losses its leader's to carry (locked, the leader's model had half
                # the fingers: the Panda's finger settled 5 mm short)
                lead, follow = model.getJointId(leader), model.getJointId(follower)
                at, own = model.joints[lead].idx_v, model.joints[follow].idx_v
                damping, friction = float(model.damping[own]), float(model.friction[own])
                model = pin.transformJointIntoMimic(model, lead, follow, scale, offset)
                model.damping[at] += scale * scale * damping
                model.friction[at] += abs(scale) * friction
        names = [model.names[i] for i in range(1, model.njoints) if model.joints[i].shortname() != "JointModelMimic"]
        if names != self.joint_names:
            raise ValueError(f"{self.name}: Pinocchio joint order {names} differs from {self.joint_names}")
        model.gravity.linear = self.base_pose[:3, :3].T @ self.gravity
        return model

    @cached_property
    def couplings(self) -> dict[str, tuple[str, float, float]]:
        """Passive joints that follow another (the MJCF's joint equalities, a URDF's ``<mimic>``): follower →
        (leader, offset, scale), ``q_follower = offset + scale·q_leader``; a polynomial coupling is left out (the
        follower is then locked in Pinocchio's model)."""
        import xml.etree.ElementTree as ET

        out = {}
        for eq in ET.fromstring(self.mjcf).iter("joint"):
            if eq.get("joint1") is None or eq.get("joint2") is None:
                continue  # (a joint element, not an equality)
            coef = [float(c) for c in (eq.get("polycoef") or "0 1 0 0 0").split()]
            follower, leader = eq.get("joint1"), eq.get("joint2")
            if follower in self.passive_joints and leader in self.joint_names and not any(coef[2:]):
                out[follower] = (leader, coef[0], coef[1])
        return out

    @cached_property
    def ee_frame_id(self) -> int:
        model = self.pin_model
        name = self.ee_body if self.ee_body is not None and model.existFrame(self.ee_body) else self.ee_site
        if not model.existFrame(name):
            frames = [f.name for f in model.frames]
            raise ValueError(f"{self.name}: end-effector '{name}' is not a frame; frames: {frames}")
        import pinocchio as pin

        # a joint's frame may share the body's name (SO-100's "gripper"): the body, then a site, is the hand
        for kind in (pin.FrameType.BODY, pin.FrameType.OP_FRAME):
            if model.existFrame(name, kind):
                return model.getFrameId(name, kind)
        return model.getFrameId(name)

    @cached_property
    def revolute(self) -> np.ndarray:
        """Which joints turn (MJCF ``hinge``, the default) rather than slide, in the order of ``q``; read from the
        MJCF itself, so robots Pinocchio can't load (closed loops) have it too."""
        import xml.etree.ElementTree as ET

        kinds = {j.get("name"): j.get("type", "hinge") for j in ET.fromstring(self.mjcf).iter("joint")}
        return np.array([kinds.get(n, "hinge") != "slide" for n in self.joint_names])

    @cached_property
    def dissipation(self) -> JointDissipation:
        """The joints' damping and Coulomb friction as the MJCF declares them (its defaults classes applied): what
        MuJoCo simulates, read by Pinocchio's parser into the model the controllers use (whose inverse dynamics
        carry the rotor inertia, ``armature``, too). None known (zeros) for a robot Pinocchio cannot model (a
        parallel mechanism's closed loops)."""
        fade = np.where(self.revolute, np.radians(FRICTION_FADE_DEG_S), FRICTION_FADE_M_S)
        try:
            model = self.pin_model
        except Exception:  # noqa: BLE001 (no dynamic model: nothing to compensate by it)
            return JointDissipation(np.zeros(self.dof), np.zeros(self.dof), fade)
        return JointDissipation(np.array(model.damping[: self.dof], float), np.array(model.friction[: self.dof], float),
                                fade)

    @cached_property
    def batch_fk(self):
        """``batch_fk(qs) -> (N, 4, 4)``: end-effector poses in the base frame, vectorised over the batch
        (:class:`rehabkit.models.batch_fk.BatchFK`)."""
        from rehabkit.models.batch_fk import BatchFK

        return BatchFK(self.pin_model, self.ee_frame_id)

    def new_pin_data(self):
        """A fresh Pinocchio data object (one per user: they are scratch space)."""
        return self.pin_model.createData()

    def ee_pose(self, q: np.ndarray, data=None) -> np.ndarray:
        """End-effector pose in the base frame, by Pinocchio."""
        import pinocchio as pin

        data = data if data is not None else self.new_pin_data()
        pin.framesForwardKinematics(self.pin_model, data, q)
        return data.oMf[self.ee_frame_id].homogeneous.copy()

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """Base-frame points (n, 3) (or one point) in the world frame, (n, 3)."""
        base = self.base_pose
        return np.asarray(points, float).reshape(-1, 3) @ base[:3, :3].T + base[:3, 3]

    def __repr__(self) -> str:
        return f"RobotModel({self.name!r}, dof={self.dof}, ee={self.ee_site!r})"
