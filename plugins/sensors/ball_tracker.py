"""Tracks a thrown object (as a VR or motion-capture system would) and judges the throws.

Each reading is the object's position in the robot's base frame and whether it is free
(away from the hand). After the run, every free flight is taken apart: where it crossed
the catch plane (x = ``catch_point[0]``), how far from the catch point, and how closely
it followed the analytic parabola fitted to its first instants (drag-free ballistics).
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from rehabkit.planning import GRAVITY
from rehabkit.plugin import Backend, Context, Metric, SceneGeometry, SceneObjects, Sensor, SensorConfig, hookimpl

FIT_SAMPLES = 20  # samples after the release used to fit the flight's initial state


class BallTrackerConfig(SensorConfig):
    """Object, catch point and tracking noise."""

    rate_hz: float = Field(1000.0, gt=0)
    object: str = Field("ball", description="world object to track")
    catch_point: tuple[float, float, float] = Field(description="robot base frame [m]; its x sets the catch plane")
    zone_radius_m: float = Field(0.05, gt=0, description="a crossing this close to the catch point counts as caught")
    free_distance_m: float = Field(0.02, gt=0, description="farther than this from the hand: in flight")
    noise_m: float = Field(0.0, ge=0, description="tracking noise (standard deviation)")


class BallTracker(Sensor):
    """Object position in the robot's base frame; flights, catch-plane crossings and parabola fits per run."""

    metrics = (
        Metric("catch_mean_error_m", "m", outcome=True,
               description="mean distance of the catch-plane crossings from the catch point"),
        Metric("catch_max_error_m", "m", description="largest distance of a crossing from the catch point"),
        Metric("catch_spread_std_m", "m", description="spread of the crossings (standard deviation)"),
        Metric("catch_spread_max_m", "m", description="largest distance between two crossings"),
        Metric("throws_crossed", "count", description="throws whose ball crossed the catch plane"),
        Metric("throws_in_zone", "count", description="throws crossing within the catch zone"),
        Metric("parabola_max_dev_mm", "mm", description="largest deviation of a flight from its fitted parabola"),
    )

    requires = (SceneGeometry, SceneObjects)

    def __init__(self, config: BallTrackerConfig, context: Context):
        self.config, self.rng = config, context.rng
        self.frame = "robot base"
        base = context.robot.model.base_pose
        self._rot, self._origin = base[:3, :3], base[:3, 3]
        self.catch = np.asarray(config.catch_point, float)
        self._t: list[float] = []
        self._p: list[np.ndarray] = []
        self._free: list[bool] = []

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict:
        world = backend.object_position(self.config.object)
        hand = backend.ee_position()
        d = world - hand if hand is not None else None
        free = d is None or math.sqrt(d @ d) > self.config.free_distance_m
        p = (world - self._origin) @ self._rot
        if self.config.noise_m:
            p = p + self.rng.normal(0.0, self.config.noise_m, 3)
        self._t.append(t)
        self._p.append(p)
        self._free.append(free)
        return {"position_m": p, "in_flight": float(free)}

    def flights(self) -> list[dict]:
        """Every free flight: its crossing of the catch plane and its deviation from the fitted parabola."""
        t, p, free = np.array(self._t), np.array(self._p).reshape(-1, 3), np.array(self._free)
        edges = np.flatnonzero(np.diff(free.astype(int)) == 1) + 1
        out = []
        for start in edges:
            stop = start
            while stop < len(free) and free[stop]:
                stop += 1
            ts, ps = t[start:stop] - t[start], p[start:stop]
            crossing = np.flatnonzero(ps[:, 0] >= self.catch[0])
            if len(ts) < FIT_SAMPLES + 2 or not len(crossing) or crossing[0] == 0:
                out.append({"t": float(t[start]), "crossed": False})
                continue
            k = crossing[0]
            f = (self.catch[0] - ps[k - 1, 0]) / (ps[k, 0] - ps[k - 1, 0])
            hit = ps[k - 1] + f * (ps[k] - ps[k - 1])
            # the flight's initial state by least squares over its first instants, gravity known
            fit_t = ts[:FIT_SAMPLES]
            gravity = np.array([0.0, 0.0, -GRAVITY]) @ self._rot  # the world's gravity in the base frame
            rhs = ps[:FIT_SAMPLES] - 0.5 * np.outer(fit_t**2, gravity)
            design = np.column_stack([np.ones_like(fit_t), fit_t])
            (p0, v0), *_ = np.linalg.lstsq(design, rhs, rcond=None)
            predicted = p0 + np.outer(ts[: k + 1], v0) + 0.5 * np.outer(ts[: k + 1] ** 2, gravity)
            out.append({"t": float(t[start]), "crossed": True, "crossing_m": hit,
                        "error_m": float(np.linalg.norm(hit - self.catch)),
                        "parabola_dev_m": float(np.linalg.norm(predicted - ps[: k + 1], axis=1).max()),
                        "release_speed_m_s": float(np.linalg.norm(v0)), "flight_s": float(ts[k])})
        return out

    def run_metrics(self, trace) -> dict[str, float]:
        flights = self.flights()
        crossed = [f for f in flights if f["crossed"]]
        out = {"throws_released": float(len(flights)), "throws_crossed": float(len(crossed))}
        if crossed:
            hits = np.array([f["crossing_m"] for f in crossed])
            errors = np.array([f["error_m"] for f in crossed])
            spread = np.linalg.norm(hits - hits.mean(axis=0), axis=1)
            out.update({
                "catch_mean_error_m": float(errors.mean()), "catch_max_error_m": float(errors.max()),
                "catch_spread_std_m": float(np.sqrt((spread**2).mean())), "catch_spread_max_m": float(spread.max()),
                "throws_in_zone": float((errors <= self.config.zone_radius_m).sum()),
                "parabola_max_dev_mm": float(max(f["parabola_dev_m"] for f in crossed) * 1e3),
            })
        return out

    def report(self, metrics: dict[str, float]) -> str | None:
        if "catch_mean_error_m" not in metrics:
            return None
        m = {k: v * 1e3 for k, v in metrics.items() if k.startswith("catch_")}
        return (f"{metrics['throws_crossed']:.0f} of {metrics['throws_released']:.0f} throws crossed the catch plane: "
                f"mean distance to the catch point {m['catch_mean_error_m']:.1f} mm "
                f"(max {m['catch_max_error_m']:.1f}), "
                f"spread std {m['catch_spread_std_m']:.1f} mm (max {m['catch_spread_max_m']:.1f}); "
                f"flight vs parabola within {metrics['parabola_max_dev_mm']:.2f} mm")


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("ball-tracker", config=BallTrackerConfig, factory=BallTracker)
