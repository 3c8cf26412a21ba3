"""A person as a recorded session had them: the wrench they put on the robot, played back from a ROS bag.

Each control step the person's joint torques are τ = J(q)ᵀ w(t): ``w`` the bag's ``geometry_msgs/WrenchStamped``
at the run's time (linear between messages, none before the first or after the last), expressed in its frame and
acting at that frame's origin, as ROS means a wrench; ``J`` that frame's Jacobian in its own axes, at the posture the
robot has now. The playback is open loop: the person pushes as they did, whatever the robot does now. This is how
``rehabkit replay BAG --scenario S.yaml`` puts a real session's person against another controller.
"""

from __future__ import annotations

import hashlib

import numpy as np
from pydantic import Field

from rehabkit.plugin import Context, Patient, SettingError, StrictModel, hookimpl
from rehabkit.recordings import BagError, read_session


class RecordedWrenchConfig(StrictModel):
    bag: str = Field(description="the ROS bag (a rosbag2 folder, an .mcap file or a ROS 1 .bag; relative to the "
                                 "scenario's folder)")
    topic: str = Field("/wrench", description="its geometry_msgs/WrenchStamped topic: the person's wrench on the robot")
    joint_states: str = Field("/joint_states", description="its sensor_msgs/JointState topic: the session starts "
                                                           "(t = 0) at its first message")
    frame: str | None = Field(None, description="the robot frame the wrench is given in and acts at (default: the "
                                                "messages' frame_id)")
    reaction: bool = Field(False, description="the sensor reports the robot's wrench on the person: played negated")
    max_gap_s: float = Field(0.5, gt=0, description="longest stretch without messages bridged by interpolation [s]")


class RecordedWrench(Patient):
    """The recorded wrench as joint torques, at the posture the robot has now."""

    def __init__(self, config: RecordedWrenchConfig, context: Context):
        import pinocchio as pin

        self._pin = pin
        topics = {"joint_states": config.joint_states, "wrench": config.topic}
        try:
            session = read_session(context.resolve(config.bag), topics, roles=("joint_states", "wrench"))
        except BagError as exc:  # the bag's own problem, said at the setting naming it
            raise SettingError("bag", str(exc.diagnostics[0])) from exc
        w = session.wrench
        if w is None:
            raise SettingError("topic", f"{context.resolve(config.bag)} has no {config.topic} "
                                        "(geometry_msgs/WrenchStamped): name the person's wrench topic")
        too_long = [g for g in session.gaps if g.topic == config.topic and g.length_s > config.max_gap_s]
        if too_long:
            raise SettingError("max_gap_s", f"{too_long[0]}: longer than {config.max_gap_s:g} s, the longest "
                                            "bridged (raise max_gap_s to bridge it by interpolation)")
        self.model = context.robot.model.pin_model
        name = config.frame or w.frame
        if not name or not self.model.existFrame(name):
            frames = ", ".join(f.name for f in self.model.frames if f.name != "universe")
            where = "frame" if config.frame else "topic"
            raise SettingError(where, f"the wrench's frame '{name}' is not a frame of robot "
                                      f"'{context.robot.model.name}' (its frames: {frames})",
                               fix="name the frame it is given in and acts at: frame")
        self.frame = self.model.getFrameId(name)
        self.data = self.model.createData()
        self.t, self.w = w.t, (-1.0 if config.reaction else 1.0) * w.values
        self.gaps = [g for g in session.gaps if g.topic == config.topic]
        self._digest = hashlib.sha256(np.ascontiguousarray(self.w).tobytes()).hexdigest()[:16]
        if context.note is not None and not context.dry_run:
            for g in self.gaps:
                context.note(g.start_s, f"recorded wrench: {g}, bridged by interpolation")

    def wrench(self, t: float) -> np.ndarray:
        """The recorded wrench (force [N], torque [N·m]) at run time ``t`` [s], in the frame it was given in."""
        if t < self.t[0] or t > self.t[-1]:
            return np.zeros(6)
        k = int(np.searchsorted(self.t, t, side="right"))
        if k >= len(self.t):
            return self.w[-1].copy()
        a = (t - self.t[k - 1]) / (self.t[k] - self.t[k - 1])
        return (1.0 - a) * self.w[k - 1] + a * self.w[k]

    def torques(self, q: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The joint torques [N·m] of wrench ``w`` (its frame's axes, at its origin) at posture ``q``."""
        pin = self._pin
        J = pin.computeFrameJacobian(self.model, self.data, q, self.frame, pin.LOCAL)
        return J.T @ w

    def torque(self, t: float, q: np.ndarray, qd: np.ndarray, goal: np.ndarray) -> np.ndarray:
        return self.torques(q, self.wrench(t))

    def inputs(self) -> dict[str, str]:
        return {"recorded_wrench": self._digest}

    def series(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {"patient/recorded_force_n": (self.t, np.linalg.norm(self.w[:, :3], axis=1))}


@hookimpl
def rehabkit_register_patients(registry) -> None:
    registry.add("recorded-wrench", config=RecordedWrenchConfig, factory=RecordedWrench)
