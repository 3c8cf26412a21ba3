"""Record a session as a lab's ROS system would, into a ROS 2 bag written by ``rosbags`` (not by rehabkit).

Runs a scenario with a simulated person and writes what the robot's side would have published: the joint states
(``sensor_msgs/JointState``: position, velocity, the torque sent), the person's wrench at the hand's cuff
(``geometry_msgs/WrenchStamped`` in the hand's frame), and each target when it was shown (``PointStamped`` in the
world). Topics can be named as another lab names them, and a stretch of the recording dropped (a recorder's hiccup)::

    python examples/ros_session/record_session.py out/session_bag
    python examples/ros_session/record_session.py out/renamed_bag --topic joint_states=/arm/joint_states \\
        --topic wrench=/cuff/wrench --topic targets=/task/targets --gap 2.0,0.3
"""

from __future__ import annotations

import argparse
import functools
import shutil
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
EPOCH_NS = 1_764_000_000 * 1_000_000_000  # the session's wall-clock start (stamps are Unix time, as a robot's are)


@functools.lru_cache(maxsize=4)
def run_session(scenario: Path):
    """The session itself: the scenario run (once per process) — its trace, plans and robot model."""
    from rehabkit.api import load_scenario
    from rehabkit.core.run.runner import Runner

    runner = Runner(load_scenario(scenario))
    result = runner.run()
    return result.trace, result.summary["plans"], runner.robot.model


def record(bag: Path, scenario: Path = HERE / "arm4_session.yaml", topics: dict[str, str] | None = None,
           gap: tuple[float, float] | None = None, storage: str = "mcap", hand_frame: str = "tip") -> dict[str, int]:
    """Run ``scenario`` and write its session to the rosbag2 folder ``bag``; returns each topic's message count."""
    import pinocchio as pin
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    topics = {"joint_states": "/joint_states", "wrench": "/wrench", "targets": "/targets", **(topics or {})}
    tr, plans, model = run_session(Path(scenario).resolve())
    pm = model.pin_model
    data, frame = pm.createData(), pm.getFrameId(hand_frame)

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vec, Point = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"]

    def header(ns: int, frame_id: str = ""):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame_id)

    def dropped(t: float) -> bool:
        return gap is not None and gap[0] <= t < gap[0] + gap[1]

    if bag.exists():
        shutil.rmtree(bag)
    counts = dict.fromkeys(topics.values(), 0)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(bag, version=8, storage_plugin=plugin) as w:
        conn = {role: w.add_connection(topics[role], msgtype, typestore=ts) for role, msgtype in (
            ("joint_states", "sensor_msgs/msg/JointState"), ("wrench", "geometry_msgs/msg/WrenchStamped"),
            ("targets", "geometry_msgs/msg/PointStamped"))}

        def put(role: str, msg, ns: int) -> None:
            w.write(conn[role], ns, ts.serialize_cdr(msg, msg.__msgtype__))
            counts[topics[role]] += 1

        for k, t in enumerate(tr.t):
            if dropped(t):
                continue
            ns = EPOCH_NS + int(round(t * 1e9))
            put("joint_states", T["sensor_msgs/msg/JointState"](
                header=header(ns), name=list(model.joint_names), position=tr.q[k].copy(), velocity=tr.qd[k].copy(),
                effort=tr.tau[k].copy()), ns)
            # the person's wrench on the cuff in the hand's frame, as a six-axis sensor there gives it: the least one
            # whose joint torques are the person's (Jᵀ w = τ_h, J the hand frame's Jacobian in its own axes)
            J = pin.computeFrameJacobian(pm, data, tr.q[k], frame, pin.LOCAL)
            f = J @ np.linalg.lstsq(J.T @ J, tr.tau_h[k], rcond=None)[0]
            put("wrench", T["geometry_msgs/msg/WrenchStamped"](header=header(ns, hand_frame), wrench=T[
                "geometry_msgs/msg/Wrench"](force=Vec(x=f[0], y=f[1], z=f[2]), torque=Vec(x=f[3], y=f[4], z=f[5]))),
                ns)
        for plan in plans[1:]:  # each target as shown: where its plan goes, in the world
            if dropped(plan["t"]):
                continue
            goal = model.ee_pose(np.radians(plan["waypoints_deg"][-1]))[:3, 3]
            p = model.to_world(goal)[0]
            ns = EPOCH_NS + int(round(plan["t"] * 1e9))
            put("targets", T["geometry_msgs/msg/PointStamped"](header=header(ns, "world"),
                                                                point=Point(x=p[0], y=p[1], z=p[2])), ns)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag", type=Path, help="the rosbag2 folder to write")
    ap.add_argument("--scenario", type=Path, default=HERE / "arm4_session.yaml")
    ap.add_argument("--topic", action="append", default=[], metavar="ROLE=TOPIC", help="name a topic otherwise")
    ap.add_argument("--gap", metavar="START,LENGTH", help="drop every message in this stretch [s]")
    ap.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    args = ap.parse_args()
    gap = tuple(float(v) for v in args.gap.split(",")) if args.gap else None
    counts = record(args.bag, args.scenario, dict(t.split("=", 1) for t in args.topic), gap, args.storage)
    print(f"wrote {args.bag}: " + ", ".join(f"{topic} {n}" for topic, n in counts.items()))


if __name__ == "__main__":
    main()
