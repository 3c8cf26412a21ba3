"""A sensor's reading as ROS messages, on topics under ``/sensors/<name>/``, as a ROS driver of such a sensor
would publish it: a force and torque as ``geometry_msgs/WrenchStamped`` (in the sensor's frame), an RGB image as
``sensor_msgs/Image`` (``rgb8``, in a frame named after the sensor), joint angles as ``sensor_msgs/JointState``
(``joint_states``, the joints named), a seen target as ``geometry_msgs/PointStamped`` (the robot's base link), a
number as ``std_msgs/Float64`` and a vector as ``std_msgs/Float64MultiArray`` (its channels named in the layout)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

Message = tuple[str, str, dict]  # (topic, message type, message)


def _vec(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _image(rgb: np.ndarray) -> bool:
    return isinstance(rgb, np.ndarray) and rgb.ndim == 3 and rgb.shape[2] == 3 and rgb.dtype == np.uint8


JOINT_KEYS = ("position_rad", "position_m")  # a joint encoder's: SI by joint type, as JointState holds them


def _joint_state(reading: dict[str, Any], channels) -> dict | None:
    """A joint encoder's reading as one JointState's names and positions (radians and metres, as ROS has them), or
    None where the sensor does not name its joints."""
    if channels is None:
        return None
    names: list[str] = []
    values: list[float] = []
    for key in JOINT_KEYS:
        if (value := reading.get(key)) is None:
            continue
        data = np.ravel(np.asarray(value, float))
        joints = channels(key, data.size)
        if not joints:
            return None
        names += joints
        values += data.tolist()
    return {"name": names, "position": values, "velocity": [], "effort": []} if names else None


def reading_messages(name: str, reading: dict[str, Any], header: dict, frame: str,
                     channels: Callable[[str, int], list[str] | None] | None = None,
                     base_link: str = "base_link") -> Iterator[Message]:
    """The messages of one reading (``header``: its stamp; ``frame``: where the sensor is; ``base_link``: the robot's
    base link, the frame of a seen target)."""
    base = f"/sensors/{name}"
    wrench = "force_n" in reading and "torque_nm" in reading
    if wrench:
        yield (f"{base}/wrench", "geometry_msgs/WrenchStamped",
               {"header": {**header, "frame_id": frame}, "wrench": {"force": _vec(reading["force_n"]),
                                                                   "torque": _vec(reading["torque_nm"])}})
    joints = _joint_state(reading, channels)  # (revolute joints in radians and prismatic in metres: one JointState)
    if joints is not None:
        yield f"{base}/joint_states", "sensor_msgs/JointState", {"header": header, **joints}
    for key, value in reading.items():
        if value is None or (wrench and key in ("force_n", "torque_nm")) or (joints and key in JOINT_KEYS):
            continue
        topic = f"{base}/{key}"
        if _image(value):
            h, w, _ = value.shape
            # (a camera's frame is its own, not one of the robot's: named after the sensor)
            yield (topic, "sensor_msgs/Image", {"header": {**header, "frame_id": name}, "height": h, "width": w,
                                                "encoding": "rgb8", "is_bigendian": 0, "step": 3 * w,
                                                "data": np.ascontiguousarray(value).tobytes()})
        elif key == "target_position":
            yield topic, "geometry_msgs/PointStamped", {"header": {**header, "frame_id": base_link},
                                                        "point": _vec(value)}
        elif np.ndim(value) == 0:
            yield topic, "std_msgs/Float64", {"data": float(value)}
        else:
            data = np.ravel(np.asarray(value, float))
            names = channels(key, data.size) if channels is not None else None
            label = ",".join(names) if names else key
            yield (topic, "std_msgs/Float64MultiArray",
                   {"layout": {"dim": [{"label": label, "size": data.size, "stride": data.size}], "data_offset": 0},
                    "data": data.tolist()})
