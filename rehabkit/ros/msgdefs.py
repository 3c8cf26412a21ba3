"""The ROS 2 message definitions a run's bag uses (common_interfaces and rcl_interfaces, as ROS 2 ships them), each
with the definitions it depends on, as rosbag2 stores a schema in an MCAP file."""

from __future__ import annotations

_OWN = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "std_msgs/Float64": "float64 data\n",
    "sensor_msgs/JointState": "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
                              "float64[] effort\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Transform": "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\n"
                                      "geometry_msgs/Transform transform\n",
    "geometry_msgs/Wrench": "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
    "geometry_msgs/WrenchStamped": "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/PointStamped": "std_msgs/Header header\ngeometry_msgs/Point point\n",
    "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
    "std_msgs/MultiArrayDimension": "string label\nuint32 size\nuint32 stride\n",
    "std_msgs/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
    "std_msgs/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
    "sensor_msgs/Image": "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
                         "uint32 step\nuint8[] data\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "rcl_interfaces/Log": "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n"
                          "builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n"
                          "string function\nuint32 line\n",
}


def _uses(name: str) -> list[str]:
    """The message types ``name``'s definition refers to, each once, depth first."""
    out: list[str] = []
    for line in _OWN[name].splitlines():
        field_type = line.split()[0].removesuffix("[]") if line and "=" not in line else ""
        if "/" in field_type:
            for dep in (*_uses(field_type), field_type):
                if dep not in out:
                    out.append(dep)
    return out


def msgdef(name: str) -> str:
    """``pkg/Type``'s definition followed by those it uses (``MSG:`` sections), as an MCAP schema's ``ros2msg``."""
    sep = "=" * 80
    return _OWN[name] + "".join(f"{sep}\nMSG: {dep}\n{_OWN[dep]}" for dep in _uses(name))


def datatype(name: str) -> str:
    """ROS 2's full type name: ``sensor_msgs/msg/JointState``."""
    pkg, msg = name.split("/")
    return f"{pkg}/msg/{msg}"
