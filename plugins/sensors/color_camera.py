"""A colour camera that finds a ball of known size and reports where it is (after Loconsole et al.).

Each reading renders the scene camera, thresholds the image in HSV, cleans the
mask, takes the largest blob's centroid and its apparent diameter, turns the
diameter into the distance along the viewing ray (a sphere of radius R seen
under a half-angle α is at R / sin α), and maps the point through the camera's
intrinsic matrix (from its field of view) and its extrinsic pose into the robot
base frame. Planning uses this estimate; the ground truth only serves the error
figures.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from pydantic import Field

from rehabkit.plugin import Backend, Cameras, Context, Metric, Sensor, SensorConfig, SettingError, hookimpl

HSV = tuple[int, int, int]


class ColorCameraConfig(SensorConfig):
    """Which camera, which colour, which ball."""

    camera: str = Field(description="a camera of the scenario's world")
    width: int = Field(640, ge=32)
    height: int = Field(480, ge=32)
    hsv_ranges: list[tuple[HSV, HSV]] = Field(
        [((0, 100, 10), (10, 255, 255)), ((170, 100, 10), (180, 255, 255))],
        description="OpenCV HSV (H 0-180) bounds of the ball colour; default red (both ends of H), any shade (V >= 10)",
    )
    ball_diameter_m: float = Field(gt=0, description="known diameter of the target ball [m]")
    min_area_px: int = Field(30, ge=1, description="smaller blobs are noise")
    truth_object: str | None = Field(None, description="scene object to measure the estimate against")
    max_edge_spread: float = Field(
        0.035, gt=0, description="spread (std/mean) of the edge rays' angles from the ball's direction beyond which "
        "the ball counts as partly hidden and the reading as a miss (whole balls: about 0.02)")


class ColorCamera(Sensor):
    """Overhead colour camera locating a ball: HSV mask, centroid, diameter → 3-D point in the robot frame."""

    metrics = (
        Metric("camera_detections", "count", description="frames where the ball was found"),
        Metric("camera_misses", "count", description="frames where the ball was not found"),
        Metric("camera_occluded", "count", description="frames where the ball was hidden by the robot"),
        Metric("camera_error_mean_mm", "mm", description="mean error of the seen ball position"),
        Metric("camera_error_max_mm", "mm", description="largest error of the seen ball position"),
    )

    requires = (Cameras,)

    blocking = True  # a frame: ~70 ms of software rendering here, several ticks on any machine

    def __init__(self, config: ColorCameraConfig, context: Context):
        self.config = config
        self.frame = "robot base"  # (target_position)
        self.base = context.robot.model.base_pose
        names = [c.name for c in context.world.cameras]
        if config.camera not in names:
            raise SettingError("camera", f"no camera '{config.camera}' in world.cameras "
                             f"({', '.join(names) or 'none'})")
        self.kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        self.errors: list[float] = []
        self.misses = self.occluded = 0

    def intrinsics(self, fovy: float) -> np.ndarray:
        """Pinhole matrix A for this image size (square pixels, principal point at the image centre)."""
        f = 0.5 * self.config.height / math.tan(0.5 * fovy)
        return np.array([[f, 0.0, (self.config.width - 1) / 2], [0.0, f, (self.config.height - 1) / 2], [0, 0, 1.0]])

    def detect(self, rgb: np.ndarray) -> tuple[np.ndarray, float] | None:
        """The largest blob of the ball's colour: its edge pixels (N, 2) and its area [px], or None.

        The area counts each pixel by how much of it the ball covers: edge
        pixels are antialiased blends, whose saturation relative to the ball's
        interior says how much ball they hold.
        """
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
        mask = np.zeros(hsv.shape[:2], np.uint8)
        hue = np.zeros(hsv.shape[:2], np.uint8)
        for lo, hi in self.config.hsv_ranges:
            mask |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
            hue |= cv2.inRange(hsv, np.array((lo[0], 5, 0), np.uint8), np.array((hi[0], 255, 255), np.uint8))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self.kernel)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            return None
        blob = max(contours, key=cv2.contourArea)
        if cv2.contourArea(blob) < self.config.min_area_px:
            return None
        solid = np.zeros_like(mask)
        cv2.drawContours(solid, [blob], -1, 255, thickness=cv2.FILLED)
        core = cv2.erode(solid, self.kernel, iterations=2) > 0
        rim = (cv2.dilate(solid, self.kernel, iterations=2) > 0) & ~core & (hue > 0)
        sat = hsv[..., 1].astype(float)
        full = np.median(sat[core]) if core.any() else 255.0
        area = core.sum() + np.clip(sat[rim] / full, 0.0, 1.0).sum()
        return blob.reshape(-1, 2).astype(float), float(area)

    def locate(self, edge: np.ndarray, area: float, cam_pos, cam_rot, fovy: float
               ) -> tuple[np.ndarray, float, np.ndarray, float]:
        """World position of the ball from its silhouette, its apparent diameter [px], centre pixel, edge spread.

        Direction: every silhouette pixel back-projects to a ray at the same
        angle α from the direction d of the ball's centre, so those unit rays
        lie on a circle of the unit sphere, and a plane fit gives d as its
        normal. Size: a small sphere seen θ off the optical axis images as an
        ellipse of area π f² tan²α / cos³θ, which gives α from the (sub-pixel)
        area. The centre is R / sin α away along d. For a whole ball every edge
        ray makes the same angle with d; the spread of those angles (std/mean)
        is returned, as a partly hidden ball shows.
        """
        A = self.intrinsics(fovy)
        rays = np.linalg.solve(A, np.column_stack([edge, np.ones(len(edge))]).T).T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        mean = rays.mean(axis=0)
        _, _, vt = np.linalg.svd(rays - mean)
        d = vt[2] if vt[2] @ mean > 0 else -vt[2]
        f = A[0, 0]
        tan_alpha = math.sqrt(area * d[2] ** 3 / math.pi) / f
        distance = 0.5 * self.config.ball_diameter_m * math.sqrt(1.0 + tan_alpha**2) / tan_alpha  # R / sin α
        pixel = A @ d
        angles = np.arccos(np.clip(rays @ d, -1.0, 1.0))
        spread = float(angles.std() / angles.mean())
        return cam_pos + cam_rot @ (distance * d), 2.0 * f * tan_alpha, pixel[:2] / pixel[2], spread

    def channels(self, key: str, width: int) -> list[str] | None:
        return ["u", "v"] if key == "pixel" else super().channels(key, width)

    def read(self, t: float, q: np.ndarray, qd: np.ndarray, backend: Backend) -> dict:
        cfg = self.config
        rgb = backend.render(cfg.camera, cfg.width, cfg.height)
        found = self.detect(rgb)
        if found is None:
            self.misses += 1
            return {"image": rgb, "target_position": None, "detected": 0.0}
        cam_pos, cam_rot, fovy = backend.camera_pose(cfg.camera)
        world, d, (u, v), spread = self.locate(*found, cam_pos, cam_rot, fovy)
        if spread > cfg.max_edge_spread:  # part of the ball is hidden: its size, hence its range, is unknown
            self.occluded += 1
            return {"image": rgb, "target_position": None, "detected": 0.0, "occluded": 1.0}
        base = self.base[:3, :3].T @ (world - self.base[:3, 3])
        shown = rgb.copy()
        cv2.circle(shown, (int(round(u)), int(round(v))), int(round(d / 2)), (0, 255, 0), 1)
        cv2.drawMarker(shown, (int(round(u)), int(round(v))), (0, 255, 0), cv2.MARKER_CROSS, 8, 1)
        out = {"image": shown, "target_position": base, "detected": 1.0, "pixel": np.array([u, v]),
               "diameter_px": d}
        if cfg.truth_object:
            err = float(np.linalg.norm(world - backend.object_position(cfg.truth_object)))
            self.errors.append(err)
            out["error_m"] = err
        return out

    def run_metrics(self, trace) -> dict[str, float]:
        out = {"camera_misses": float(self.misses), "camera_occluded": float(self.occluded)}
        if self.errors:
            e = np.array(self.errors) * 1e3
            out.update(camera_error_mean_mm=float(e.mean()), camera_error_max_mm=float(e.max()),
                       camera_detections=float(len(e)))
        return out


@hookimpl
def rehabkit_register_sensors(registry) -> None:
    registry.add("color-camera", config=ColorCameraConfig, factory=ColorCamera)
