"""Balance of a standing floating-base robot: CoM margin in the support polygon, feet slip, pelvis tilt.

Reads the true pelvis state from the backend (an IMU and leg odometry would estimate
it on hardware) and the joints, and computes with the robot's floating Pinocchio model.
The support polygon is the convex hull of the foot-corner frames at the first reading.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from pydantic import Field
from scipy.spatial import ConvexHull

from rehabkit.plugin import (
    Backend,
    BaseState,
    Context,
    FloatingBase,
    Metric,
    Sensor,
    SensorConfig,
    SettingError,
    hookimpl,
)


class BalanceConfig(SensorConfig):
    """Frames spanning the support polygon, and the feet."""

    rate_hz: float = Field(1000.0, gt=0)
    support_frames: list[str] = Field(min_length=3, description="foot corner frames")
    feet: list[str] = Field(["l_sole", "r_sole"], min_length=1)


class Balance(Sensor):
    """CoM margin to the support polygon's edges, feet displacement and pelvis tilt, every reading."""

    metrics = (
        Metric("com_margin_min_m", "m",
               description="smallest distance of the CoM projection inside the support polygon"),
        Metric("feet_slip_max_mm", "mm", description="largest slip of a foot on the floor"),
        Metric("pelvis_tilt_max_deg", "deg", description="largest tilt of the pelvis from upright"),
    )

    requires = (FloatingBase, BaseState)

    def __init__(self, config: BalanceConfig, context: Context):
        robot = context.robot
        self.robot, self.config = robot, config
        self.model = robot.floating_model
        self.data = self.model.createData()
        for f in config.support_frames + config.feet:
            if not self.model.existFrame(f):
                raise SettingError("support_frames" if f in config.support_frames else "feet",
                                   f"no frame '{f}' in robot '{robot.model.name}'")
        self._corners = [self.model.getFrameId(f) for f in config.support_frames]
        self._feet = [self.model.getFrameId(f) for f in config.feet]
        self._polygon = None
        self._feet_xyz = np.zeros((len(self._feet), 3))
        # views into the data, rewritten in place by each reading's kinematics (Pinocchio's accessors wrap new ones
        # on every call)
        self._feet_rows = [(f, self.data.oMf[f].translation, self._feet_xyz[k]) for k, f in enumerate(self._feet)]
        self._pelvis_rot = self.data.oMi[1].rotation
        self.margin_min, self.slip_max, self.tilt_max = np.inf, 0.0, 0.0

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict[str, float]:
        pos, quat, _, _ = backend.base_state()
        qf = self.robot.pin_configuration(np.asarray(q, float), pos, quat)
        com = pin.centerOfMass(self.model, self.data, qf)
        for f, now, row in self._feet_rows:  # only the frames read: every frame's placement costs more
            pin.updateFramePlacement(self.model, self.data, f)
            row[:] = now
        feet = self._feet_xyz
        if self._polygon is None:
            pin.updateFramePlacements(self.model, self.data)
            pts = np.array([self.data.oMf[f].translation[:2] for f in self._corners])
            hull = ConvexHull(pts)
            self._polygon = (hull.equations[:, :2], -hull.equations[:, 2])
            self._feet0 = feet.copy()
        normals, offsets = self._polygon
        margin = min((offsets - normals @ com[:2]).tolist())  # Python's min/max: ndarray.min costs ~2 us at this size
        slip = max(map(abs, (feet - self._feet0).ravel().tolist()))
        up_z = self._pelvis_rot[2, 2]  # the pelvis' z axis, its world z component
        tilt = math.degrees(math.acos(min(1.0, max(-1.0, up_z))))
        self.margin_min = min(self.margin_min, margin)
        self.slip_max, self.tilt_max = max(self.slip_max, slip), max(self.tilt_max, tilt)
        return {"com_margin_m": margin, "feet_slip_mm": slip * 1e3, "pelvis_tilt_deg": tilt}

    def run_metrics(self, trace) -> dict[str, float]:
        if self._polygon is None:
            return {}
        return {"com_margin_min_m": self.margin_min, "feet_slip_max_mm": self.slip_max * 1e3,
                "pelvis_tilt_max_deg": self.tilt_max}


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("balance", config=BalanceConfig, factory=Balance)
