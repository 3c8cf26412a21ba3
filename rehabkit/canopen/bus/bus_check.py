"""What ``validate`` knows of a CANopen bus before anything runs: one drive per joint, node ids unique and in range,
each EDS there and holding the objects the backend maps and sets, cyclic synchronous torque supported, and the
cyclic traffic within the bitrate at the control rate (refused with the arithmetic and the highest rate that fits)."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

from rehabkit.canopen.bus.pdo_layout import RPDO, SENSOR_TPDO, TORQUE_ACTUAL, TPDO1, TPDO2, BusLoad, bus_load
from rehabkit.canopen.config import CanopenConfig, DriveSpec, SensorSpec
from rehabkit.core.kinds.errors import SettingError
from rehabkit.core.kinds.interfaces import Context

# what the backend writes by SDO besides the PDOs' objects: (index, subindex)
SET = ((0x1006, 0), (0x1016, 1), (0x1017, 0), (0x605A, 0), (0x6060, 0), (0x6072, 0), (0x607D, 1), (0x607D, 2),
       (0x6080, 0), (0x6085, 0), (0x60C2, 1), (0x60C2, 2), (0x1400, 1), (0x1600, 1), (0x1800, 1), (0x1A00, 1),
       (0x1801, 1), (0x1A01, 1))
SUPPORTED = {"csp": 0x80, "csv": 0x100, "cst": 0x200}  # 0x6502 bits 7, 8, 9
MODE_NAMES = {"csp": "cyclic synchronous position", "csv": "cyclic synchronous velocity",
              "cst": "cyclic synchronous torque"}


SENSOR_SET = ((0x1006, 0), (0x1016, 1), (0x1017, 0), (0x1800, 1), (0x1A00, 1), (0x2100, 0))


def drive_specs(config: CanopenConfig, dof: int) -> list[DriveSpec]:
    """The drives as written, or node ids 1..dof on the generic servo."""
    return list(config.drives) if config.drives is not None else [DriveSpec(node_id=i + 1) for i in range(dof)]


def sensor_specs(config: CanopenConfig, instruments: int) -> list[SensorSpec]:
    """The instruments' sensors as written, or node ids 64.. on the generic three-axis sensor."""
    return list(config.sensors) if config.sensors is not None else [
        SensorSpec(node_id=64 + k) for k in range(instruments)]


def _objects(path: str) -> tuple[frozenset, int | None]:
    """The (index, subindex) pairs an EDS holds, and its supported drive modes (0x6502) if given (read once per
    version of the file)."""
    stat = Path(path).stat()
    return _read_objects(path, stat.st_mtime_ns, stat.st_size)


@lru_cache(maxsize=16)
def _read_objects(path: str, mtime_ns: int, size: int) -> tuple[frozenset, int | None]:
    import canopen

    od = canopen.import_od(path)
    have = set()
    for index in od.indices:
        obj = od[index]
        if hasattr(obj, "subindices"):
            have.update((index, sub) for sub in obj.subindices)
        else:
            have.add((index, 0))
    modes = od[0x6502].default if 0x6502 in od else None
    return frozenset(have), modes


def _check_eds(config: CanopenConfig, spec: DriveSpec | SensorSpec, i: int, context: Context) -> None:
    if spec.eds is None:
        return
    path = context.resolve(spec.eds)
    sensor = isinstance(spec, SensorSpec)
    where = ("sensors" if sensor else "drives", i, "eds")
    if not path.is_file():
        raise SettingError(where, f"no such file: {path}")
    try:
        have, modes = _objects(str(path))
    except Exception as exc:  # noqa: BLE001 (canopen's parser: whatever it refuses, said at the file's setting)
        raise SettingError(where, f"canopen cannot read {path.name} as an EDS/DCF: {exc}") from None
    needed = [*((x, s) for x, s, _ in (*RPDO[spec.mode], *TPDO1, *TPDO2)), *SET] if not sensor else []
    if sensor:
        needed = [*((x, s) for x, s, _ in SENSOR_TPDO), *SENSOR_SET]
    elif config.torque_actual:
        needed.append(TORQUE_ACTUAL[:2])
    missing = [f"0x{x:04X}" + (f"sub{s}" if s else "") for x, s in needed if (x, s) not in have]
    if missing:
        what = "a CiA 404 device's EDS with three inputs at 0x7130" if sensor else \
            "a CiA 402 drive's EDS with two RPDOs and two TPDOs"
        raise SettingError(where, f"{path.name} lacks objects the backend maps or sets: {', '.join(missing)} (is it "
                           f"{what}?)")
    if not sensor and modes is not None and not modes & SUPPORTED[spec.mode]:
        bit = SUPPORTED[spec.mode].bit_length() - 1
        raise SettingError(("drives", i, "mode"), f"{path.name} says the drive does not support "
                           f"{MODE_NAMES[spec.mode]} (0x6502 = 0x{modes:08X}, bit {bit} clear)")


def check_bus(config: CanopenConfig, context: Context) -> tuple[list[DriveSpec], list[SensorSpec], BusLoad]:
    """The drives for the run's robot, the sensors for its instruments, and the bus load; a :class:`SettingError`
    at the setting that is wrong."""
    robot = context.robot.model
    specs = drive_specs(config, robot.dof)
    if len(specs) != robot.dof:
        raise SettingError("drives", f"{len(specs)} drives for the {robot.dof} joints of robot '{robot.name}' "
                           f"({', '.join(robot.joint_names)}): one drive per joint, in that order")
    seen: dict[int, int] = {}
    for i, s in enumerate(specs):
        if s.node_id in seen:
            raise SettingError(("drives", i, "node_id"), f"node id {s.node_id} is drive {seen[s.node_id]}'s too: each "
                               "node on a bus has its own")
        if s.node_id == config.master_node_id:
            raise SettingError(("drives", i, "node_id"), f"node id {s.node_id} is the host's (master_node_id)")
        seen[s.node_id] = i
        _check_eds(config, s, i, context)
    sensors = sensor_specs(config, len(context.instruments))
    if len(sensors) != len(context.instruments):
        names = ", ".join(i.name for i in context.instruments) or "none"
        raise SettingError("sensors", f"{len(sensors)} sensors for the run's {len(context.instruments)} instruments "
                           f"({names}): one three-axis sensor each, in that order")
    for k, s in enumerate(sensors):
        if s.node_id in seen or s.node_id == config.master_node_id:
            whose = "the host's" if s.node_id == config.master_node_id else f"drive {seen[s.node_id]}'s"
            raise SettingError(("sensors", k, "node_id"), f"node id {s.node_id} is {whose} too: each node on a bus has "
                               "its own")
        seen[s.node_id] = len(specs) + k
        _check_eds(config, s, k, context)
    if config.clock == "lockstep" and config.bus is not None:
        raise SettingError("clock", "lockstep runs the simulated drives only (a real bus runs in real time): remove "
                           "`bus` or set clock: realtime")
    nodes = {s.node_id for s in specs}
    for i, f in enumerate(config.inject):
        if config.bus is not None:
            raise SettingError(("inject", i), "faults are injected into simulated drives only: remove `bus`")
        if f.fault == "host-stall" and config.clock == "lockstep":
            raise SettingError(("inject", i, "fault"), "a host stall is a gap in the wall clock's SYNCs: on a "
                               "lock-step bus the drives' clock stops with it (use clock: realtime)")
        if f.node is not None and f.node not in nodes:
            raise SettingError(("inject", i, "node"), f"no drive has node id {f.node} (the drives: "
                               f"{', '.join(map(str, sorted(nodes)))})")
    rate = 1.0 / context.control_dt
    following = [i for i, s in enumerate(specs) if s.mode != "cst"]
    if following and context.reference_space != "joint":
        raise SettingError(("drives", following[0], "mode"), f"a {specs[following[0]].mode} drive follows the plan's "
                           "joint reference: this scenario's planner plans in Cartesian space (use mode: cst, or a "
                           "joint-space planner)")
    reactions = context.safety.reactions if context.safety is not None else {}
    soft = [r for r, x in reactions.items() if x.type != "stop"]
    if following and soft:
        raise SettingError(("drives", following[0], "mode"), f"a {specs[following[0]].mode} drive holds its target "
                           f"stiffly: the envelope's {soft[0]} reaction ({reactions[soft[0]].type}) needs the torque "
                           "(mode: cst)")
    load = bus_load(len(specs), rate, config.bitrate, config.torque_actual, config.heartbeat_ms, len(sensors),
                    len(following))
    if load.load > 1.0:
        what = f"{len(specs)} drives" + (f" and {len(sensors)} sensors" if sensors else "")
        step = config.timestep if config.bus is None or config.bus.simulated else 1e-4
        raise SettingError(("rates", "control_hz"), f"the CAN bus cannot carry {what} at {rate:g} Hz: "
                           f"{load.describe()}; set rates.control_hz: {_fitting(load, step)} (the highest rate that "
                           f"fits{_steps(step)}; the bus carries up to {math.floor(load.highest_rate_hz())} Hz), "
                           + (f"raise backend.bitrate (now {config.bitrate}; CAN's top: 1000000), "
                              if config.bitrate < 1_000_000 else "") + "or put fewer nodes on this bus", root=True)
    return specs, sensors, load


def _steps(step: float) -> str:
    return f" in whole {step * 1e3:g} ms steps of the simulated drives' plant" if step >= 1e-3 else ""


def _fitting(load: BusLoad, step: float) -> str:
    """The highest control rate the bus carries whose period is a whole number of ``step``s."""
    k = max(1, math.ceil(1.0 / (load.highest_rate_hz() * step) - 1e-9))
    return f"{1.0 / (k * step):g}"
