"""Record a session as a lab's ROS system would, into a ROS 2 bag written by ``rosbags`` (not by rehabkit).

Runs a scenario with a simulated person and writes what the robot's side would have published: the joint states
(``sensor_msgs/JointState``: position, velocity, the torque sent), the person's wrench at the hand's cuff
(``geometry_msgs/WrenchStamped`` in the hand's frame, as a six-axis sensor there gives it), and each target when it
was shown (``PointStamped`` in the world; ``PoseStamped`` where the session's targets set the hand's orientation).
Topics can be named as another lab names them, and a stretch of the recording dropped (a recorder's hiccup)::

    python examples/ros_session/record_session.py out/session
    python examples/ros_session/record_session.py out/renamed --topic joint_states=/arm/joint_states \\
        --topic wrench=/cuff/wrench --topic targets=/task/targets --gap 2.0,0.3
"""

from __future__ import annotations

import argparse
import functools
import shutil
from pathlib import Path

import numpy as np

from rehabkit.models.hand_force import least_wrenches

HERE = Path(__file__).resolve().parent
EPOCH_NS = 1_764_000_000 * 1_000_000_000  # the session's wall-clock start (stamps are Unix time, as a robot's are)
TOPICS = {"joint_states": "/joint_states", "wrench": "/wrench", "targets": "/targets"}


@functools.lru_cache(maxsize=4)
def run_session(scenario: Path):
    """The session itself: the scenario run (once per process) — its trace, plans, robot model and task targets."""
    from rehabkit.api import load_scenario
    from rehabkit.core.run.runner import Runner

    runner = Runner(load_scenario(scenario))
    result = runner.run()
    return result.trace, result.summary["plans"], runner.robot.model, runner.sc.task.targets


def record(bag: Path, scenario: Path = HERE / "arm4_session.yaml", topics: dict[str, str] | None = None,
           gap: tuple[float, float] | None = None, storage: str = "mcap", hand_frame: str | None = None
           ) -> dict[str, int]:
    """Run ``scenario`` and write its session to the rosbag2 folder ``bag`` (the wrench in ``hand_frame``, default
    the robot's end effector); returns each topic's message count."""
    topics = {**TOPICS, **(topics or {})}
    tr, plans, model, specs = run_session(Path(scenario).resolve())
    pm = model.pin_model
    hand_frame = hand_frame or pm.frames[model.ee_frame_id].name
    if not pm.existFrame(hand_frame):
        raise SystemExit(f"error: --hand-frame {hand_frame}: not a frame of robot '{model.name}' (its frames: "
                         f"{', '.join(f.name for f in pm.frames[1:])})")
    if tr.tau_h is None:
        raise SystemExit(f"error: {scenario} has no simulated person: there is no wrench to record")
    # the person's wrench on the cuff, as a six-axis sensor in the hand's frame measures it
    wrench = least_wrenches(pm, tr.q, tr.tau_h, pm.getFrameId(hand_frame))
    world = np.asarray(model.base_pose, float)
    shown = [(p["t"], world @ model.ee_pose(np.radians(p["waypoints_deg"][-1])))
             for p in plans[1:]]  # each target as shown: the pose its plan reaches, in the world
    oriented = any(t.rpy_deg is not None or t.orientation_of is not None for t in specs)
    if bag.exists():
        shutil.rmtree(bag)
    try:
        return _write(bag, storage, topics, tr, list(model.joint_names), wrench, hand_frame, shown, oriented, gap)
    except BaseException:  # nothing half-written left behind
        shutil.rmtree(bag, ignore_errors=True)
        raise


def _write(bag: Path, storage: str, topics: dict[str, str], tr, names: list[str], wrench: np.ndarray,
           hand_frame: str, shown: list, oriented: bool, gap: tuple[float, float] | None) -> dict[str, int]:
    import pinocchio as pin
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vec, Point, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]

    def header(ns: int, frame_id: str = ""):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame_id)

    def dropped(t: float) -> bool:
        return gap is not None and gap[0] <= t < gap[0] + gap[1]

    counts = dict.fromkeys(topics.values(), 0)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(bag, version=8, storage_plugin=plugin) as w:
        conn = {role: w.add_connection(topics[role], msgtype, typestore=ts) for role, msgtype in (
            ("joint_states", "sensor_msgs/msg/JointState"), ("wrench", "geometry_msgs/msg/WrenchStamped"),
            ("targets", "geometry_msgs/msg/PoseStamped" if oriented else "geometry_msgs/msg/PointStamped"))}

        def put(role: str, msg, ns: int) -> None:
            w.write(conn[role], ns, ts.serialize_cdr(msg, msg.__msgtype__))
            counts[topics[role]] += 1

        for k, t in enumerate(tr.t):
            if dropped(t):
                continue
            ns = EPOCH_NS + int(round(t * 1e9))
            put("joint_states", T["sensor_msgs/msg/JointState"](
                header=header(ns), name=names, position=tr.q[k].copy(), velocity=tr.qd[k].copy(),
                effort=tr.tau[k].copy()), ns)
            f = wrench[k]
            put("wrench", T["geometry_msgs/msg/WrenchStamped"](header=header(ns, hand_frame), wrench=T[
                "geometry_msgs/msg/Wrench"](force=Vec(x=f[0], y=f[1], z=f[2]), torque=Vec(x=f[3], y=f[4], z=f[5]))),
                ns)
        for t, pose in shown:
            if dropped(t):
                continue
            ns, p = EPOCH_NS + int(round(t * 1e9)), pose[:3, 3]
            point = Point(x=p[0], y=p[1], z=p[2])
            if oriented:  # the hand's orientation too, where the session's targets set one
                r = pin.Quaternion(pose[:3, :3])
                put("targets", T["geometry_msgs/msg/PoseStamped"](header=header(ns, "world"), pose=T[
                    "geometry_msgs/msg/Pose"](position=point, orientation=Quat(x=r.x, y=r.y, z=r.z, w=r.w))), ns)
            else:
                put("targets", T["geometry_msgs/msg/PointStamped"](header=header(ns, "world"), point=point), ns)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag", type=Path, help="the rosbag2 folder to write")
    ap.add_argument("--scenario", type=Path, default=HERE / "arm4_session.yaml",
                    help="a scenario with a simulated person (default: the 4-joint arm's session)")
    ap.add_argument("--topic", action="append", default=[], metavar="ROLE=TOPIC",
                    help="name a topic otherwise (roles: joint_states, wrench, targets)")
    ap.add_argument("--gap", metavar="START,LENGTH", help="drop every message in this stretch [s]")
    ap.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    ap.add_argument("--hand-frame", help="the frame the wrench is given in (default: the robot's end effector)")
    args = ap.parse_args()
    gap = tuple(float(v) for v in args.gap.split(",")) if args.gap else None
    counts = record(args.bag, args.scenario, dict(t.split("=", 1) for t in args.topic), gap, args.storage,
                    args.hand_frame)
    print(f"wrote {args.bag}: " + ", ".join(f"{topic} {n}" for topic, n in counts.items()))


if __name__ == "__main__":
    main()
