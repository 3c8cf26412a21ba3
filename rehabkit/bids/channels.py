"""What a run's motion files hold: one tracking system per robot, at the control rate, and one per instrument at its
own rate (a joint encoder's angles, a force-torque sensor's wrench), each a table of channels.

Motion-BIDS has a type for joint angles (JNTANG) and positions (POS), none for a joint's speed, torque or force, or for
a reference: those are MISC, with their units and a description. A revolute joint is in degrees, a prismatic one in
metres (its speed in m/s, its force in N), wherever rehabkit shows it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rehabkit.bids.bag_arrays import Stream
from rehabkit.bids.run_folder import ExportError, RunFolder, label

# decimals printed, by unit: finer than any sensor rehabkit reads (a 16-bit encoder's count is 0.0055°)
DECIMALS = {"deg": 5, "deg/s": 3, "N.m": 4, "N": 3, "m": 6, "m/s": 5}


@dataclass(frozen=True)
class Channel:
    """A row of ``channels.tsv``."""

    name: str
    type: str  # JNTANG, POS or MISC
    units: str
    tracked_point: str
    description: str
    component: str = "n/a"
    reference_frame: str = "n/a"

    @property
    def decimals(self) -> int:
        return DECIMALS[self.units]


@dataclass
class Tracksys:
    """One tracking system: its ``label`` (``tracksys-<label>``), channels, samples (n, channels) and their stamps
    [ns], its nominal rate [Hz], and what it is (``name``, the hardware's maker and model)."""

    label: str
    name: str
    channels: list[Channel]
    data: np.ndarray
    stamps: np.ndarray
    rate_hz: float
    frames: dict[str, str] = field(default_factory=dict)  # reference frames its channels use → description

    def counts(self) -> dict[str, int]:
        types = [c.type for c in self.channels]
        return {t: types.count(t) for t in dict.fromkeys(types)}


def _on(stamps: np.ndarray, stream: Stream | None, values: np.ndarray | None = None) -> np.ndarray | None:
    """``stream``'s values (or ``values``, its rows) at the stamps where it has a message, NaN elsewhere."""
    if stream is None:
        return None
    values = stream.values if values is None else values
    out = np.full((len(stamps), values.shape[1]), np.nan)
    at = np.searchsorted(stamps, stream.stamps)
    ok = (at < len(stamps)) & (stamps[np.minimum(at, len(stamps) - 1)] == stream.stamps)
    out[at[ok]] = values[ok]
    return out


def _in_units(values: np.ndarray, revolute: np.ndarray) -> np.ndarray:
    return np.where(revolute, np.degrees(values), values)


def _rate(stamps: np.ndarray) -> float:
    return float(round(1e9 / np.median(np.diff(stamps)), 6)) if len(stamps) > 1 else 0.0


def robot_tracksys(run: RunFolder) -> Tracksys:
    """The robot's tracking system at the control rate: each joint's angle (JNTANG), speed, torque and reference
    (MISC), the interaction force and the person's wrench where the run had them (MISC), the hand's position (POS)."""
    model = run.robot.model
    js = run.bag.streams["/joint_states"]
    names, revolute = list(model.joint_names), np.asarray(model.revolute, bool)
    if js.names != names:
        raise ExportError(run.path / "run.mcap", f"/joint_states names the joints {js.names}, the run's robot "
                          f"{names}", "give the bag this run wrote")
    stamps = js.stamps
    hand = model.pin_model.frames[model.ee_frame_id].name
    rows: list[tuple[Channel, np.ndarray]] = []
    for j, joint in enumerate(names):
        turn = bool(revolute[j])
        what = "angle" if turn else "position (prismatic joint)"
        rows.append((Channel(f"{joint}_angle", "JNTANG", "deg" if turn else "m", joint, f"{joint}: measured {what}, "
                             "as the robot's joint state reports it each control step", reference_frame="joint"),
                     _in_units(js.values[:, j], turn)))
    if js.velocity is not None:
        for j, joint in enumerate(names):
            rows.append((Channel(f"{joint}_speed", "MISC", "deg/s" if revolute[j] else "m/s", joint,
                                 f"{joint}: measured joint speed", reference_frame="joint"),
                         _in_units(js.velocity[:, j], revolute[j])))
    if js.effort is not None:
        for j, joint in enumerate(names):
            rows.append((Channel(f"{joint}_torque", "MISC", "N.m" if revolute[j] else "N", joint,
                                 f"{joint}: {'torque' if revolute[j] else 'force'} sent to the drive, after the "
                                 "safety layer (clipped to the effort limit)", reference_frame="joint"),
                         js.effort[:, j]))
    ref = _on(stamps, run.bag.streams.get("/reference/joint_states"))
    if ref is not None:
        for j, joint in enumerate(names):
            rows.append((Channel(f"{joint}_reference", "MISC", "deg" if revolute[j] else "m", joint,
                                 f"{joint}: the reference the controller tracked (n/a where it had none: a stop, a "
                                 "hold)", reference_frame="joint"), _in_units(ref[:, j], revolute[j])))
    force = _on(stamps, run.bag.streams.get("/interaction_force"))
    if force is not None:
        rows.append((Channel("interaction_force", "MISC", "N", "hand", "magnitude of the person-robot interaction "
                             "force the safety layer checked: a force-torque sensor's, or the person's (a "
                             "musculoskeletal model's largest cuff force)"), force[:, 0]))
    wrench_stream = run.bag.streams.get("/wrench")
    wrench = _on(stamps, wrench_stream)
    frames = {"base": "the robot's base frame (x, y, z in metres; where the scenario's robot.base pose puts it in "
                      "the world, z up)", "joint": "each joint's own angle, as the robot's model defines it"}
    if wrench is not None:
        frame = wrench_stream.frame or hand
        frames[frame] = f"the hand frame '{frame}' of the robot's model (moves with the hand)"
        for i, (kind, axis) in enumerate((k, a) for k in ("force", "torque") for a in "xyz"):
            rows.append((Channel(f"wrench_{kind}_{axis}", "MISC", "N" if kind == "force" else "N.m", "hand",
                                 f"the person's wrench at the hand, {kind} along {axis}: the least wrench whose joint "
                                 "torques are the person's", axis, frame), wrench[:, i]))
    xyz = run.robot.fk_batch(js.values)[:, :3, 3]
    for i, axis in enumerate("xyz"):
        rows.append((Channel(f"hand_{axis}", "POS", "m", "hand", f"the hand ('{hand}') position, {axis}, by the "
                             "robot's forward kinematics of the measured joints", axis, "base"), xyz[:, i]))
    robot = run.summary.get("plugins", {}).get("robot", {})
    return Tracksys(label(robot.get("type") or model.name) or "robot", f"{robot.get('type', model.name)} robot",
                    [c for c, _ in rows], np.column_stack([v for _, v in rows]), stamps,
                    _control_rate(run, stamps), frames)


def _control_rate(run: RunFolder, stamps: np.ndarray) -> float:
    rates = run.scenario.get("rates") or {}
    return float(rates.get("control_hz") or _rate(stamps))


def instrument_tracksys(run: RunFolder, taken: set[str]) -> list[Tracksys]:
    """A tracking system per instrument the bag holds readings of, at its own rate: a joint encoder's angles
    (JNTANG), a force-torque sensor's wrench (MISC, in its frame)."""
    out: list[Tracksys] = []
    model = run.robot.model
    revolute = dict(zip(model.joint_names, np.asarray(model.revolute, bool)))
    sensors = run.scenario.get("sensors") or {}
    for topic, s in sorted(run.bag.streams.items()):
        parts = topic.strip("/").split("/")
        if len(parts) != 3 or parts[0] != "sensors" or len(s.stamps) < 2:
            continue
        name, kind = parts[1], parts[2]
        tag = label(name)
        if not tag or tag in taken:
            continue
        spec = sensors.get(name) or {}
        rate = float(spec.get("rate_hz") or _rate(s.stamps))
        what = f"{spec.get('type', 'sensor')} '{name}'"
        if kind == "joint_states":
            turns = np.array([revolute.get(j, True) for j in s.names], bool)
            chans = [Channel(f"{j}_angle", "JNTANG", "deg" if t else "m", j, f"{j}: the {what}'s reading",
                             reference_frame="joint") for j, t in zip(s.names, turns)]
            data = _in_units(s.values, turns)
            frames = {"joint": "each joint's own angle, as the robot's model defines it"}
        elif kind == "wrench":
            chans = [Channel(f"{k}_{a}", "MISC", "N" if k == "force" else "N.m", s.frame or name,
                             f"the {what}'s {k} along {a}, in its frame", a, s.frame or name)
                     for k in ("force", "torque") for a in "xyz"]
            data = s.values
            frames = {s.frame or name: f"the {what}'s own frame"}
        else:
            continue
        taken.add(tag)
        out.append(Tracksys(tag, what, chans, data, s.stamps, rate, frames))
    return out
