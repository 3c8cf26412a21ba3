"""Rerun's pieces for a run's recording: colours, a model's shapes as archetypes, images, buffered columns."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr

from rehabkit.core.kinds.interfaces import GeomVisual

# a joint's colour (measured: full, reference: paler and thinner), the same in every panel; Rerun's own palette order
PALETTE = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
           (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207))
LIMIT_RGB = (110, 110, 110)


def rgba(c) -> list[int]:
    return [int(round(255 * v)) for v in c]


def rgba_rows(values) -> np.ndarray | None:
    return None if values is None else np.round(255 * np.clip(np.asarray(values, float), 0, 1)).astype(np.uint8)


@functools.cache
def _strip_type() -> pa.DataType:
    """The Arrow type of Rerun's ``LineStrip3D`` component, as the SDK's public API makes it (one strip, once)."""
    return rr.components.LineStrip3DBatch([np.zeros((2, 3), np.float32)]).as_arrow_array().type


def strips(points: np.ndarray, lengths: np.ndarray) -> pa.Array:
    """Polylines as the Arrow array of Rerun's ``LineStrip3D`` component: ``points`` (n, 3) one after another,
    ``lengths`` the points in each. Rerun's own conversion of a list of arrays costs ~15 µs a line (a person's 63
    muscle paths at the log rate would add ~15 % to a recorded run); this is one copy."""
    offsets = np.zeros(len(lengths) + 1, np.int32)
    np.cumsum(lengths, out=offsets[1:])
    kind = _strip_type()
    xyz = pa.FixedSizeListArray.from_arrays(pa.array(np.asarray(points, np.float32).ravel()), type=kind.value_type)
    return pa.ListArray.from_arrays(pa.array(offsets), xyz, type=kind)


def xyzw(wxyz: np.ndarray) -> np.ndarray:
    return np.asarray(wxyz)[..., [1, 2, 3, 0]]


def shape(g: GeomVisual):
    """A Rerun archetype for a primitive, in the geom's own frame."""
    color = [rgba(g.rgba)]
    if g.shape == "sphere":
        return rr.Ellipsoids3D(half_sizes=[[g.size[0]] * 3], colors=color, fill_mode="solid")
    if g.shape == "ellipsoid":
        return rr.Ellipsoids3D(half_sizes=[g.size], colors=color, fill_mode="solid")
    if g.shape == "box":
        return rr.Boxes3D(half_sizes=[g.size], colors=color, fill_mode="solid")
    if g.shape == "plane":
        return rr.Boxes3D(half_sizes=[[g.size[0], g.size[1], 0.001]], colors=color, fill_mode="solid")
    if g.shape == "cylinder":
        return rr.Cylinders3D(lengths=[2 * g.size[1]], radii=[g.size[0]], colors=color, fill_mode="solid")
    if g.shape == "mesh" and g.mesh is not None:
        return rr.Mesh3D(vertex_positions=g.mesh[0], triangle_indices=g.mesh[1], albedo_factor=color[0])
    if g.shape == "capsule":  # Rerun's capsule starts at the origin; MuJoCo's is centred
        return rr.Capsules3D(lengths=[2 * g.size[1]], radii=[g.size[0]], translations=[[0, 0, -g.size[1]]],
                             colors=color, fill_mode="solid")
    return None


def is_image(value: Any) -> bool:
    """An RGB image as sensors give them: ``HxWx3`` uint8."""
    return isinstance(value, np.ndarray) and value.ndim == 3 and value.shape[2] == 3 and value.dtype == np.uint8


def encode_image(rgb: np.ndarray) -> rr.EncodedImage:
    """JPEG for the log (OpenCV's encoder: ~4x faster than Rerun's own here, and it lets other threads run)."""
    import cv2  # only runs with cameras pay for importing OpenCV

    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise ValueError("could not encode an image for the log")
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg")


def encode_images(reading: dict[str, Any]) -> dict[str, Any]:
    """The reading with its images encoded for the log (done where the reading is made, off the loop)."""
    return {k: encode_image(v) if is_image(v) else v for k, v in reading.items()}



def paler(rgb: tuple[int, int, int]) -> list[int]:
    return [int(v + 0.55 * (255 - v)) for v in rgb]


def entity_part(name: str) -> str:
    """A model's name as one entity-path part (MyoSuite names hold spaces, which Rerun warns about)."""
    return name.replace(" ", "_")

class Column:
    """One sensor value's readings, appended in place (no per-sample list to convert at the flush)."""

    def __init__(self, width: int, what: str):
        self.t, self.values, self.n, self.what = np.empty(256), np.empty((256, width)), 0, what

    def append(self, t: float, value) -> None:
        n = self.n
        if n == len(self.t):
            self.t = np.resize(self.t, 2 * n)
            self.values = np.resize(self.values, (2 * n, self.values.shape[1]))
        try:
            self.values[n] = value
        except ValueError:
            raise ValueError(f"{self.what}: {np.size(value)} values, {self.values.shape[1]} in its earlier "
                             "readings (a reading's arrays keep their size; log a changing set as points)") from None
        self.t[n] = t
        self.n = n + 1

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """The buffered (times, values), copied; the buffer starts over."""
        n, self.n = self.n, 0
        return self.t[:n].copy(), self.values[:n].copy()


def in_degrees(key: str) -> tuple[str, float]:
    """A reading's key as the log shows it, and the factor to its values: angles in degrees throughout
    (``position_rad`` → ``position_deg``, × 180/π)."""
    for rad, deg in (("_rad_s", "_deg_s"), ("_rad", "_deg")):
        if key.endswith(rad):
            return key[: -len(rad)] + deg, 180.0 / np.pi
    return key, 1.0
