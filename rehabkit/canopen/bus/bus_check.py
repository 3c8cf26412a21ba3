"""What ``validate`` knows of a CANopen bus before anything runs: one drive per joint, node ids unique and in range,
each EDS/DCF read as the master reads it — the objects the backend sets there, the mode supported (0x6502), its units
convertible, a PDO for every object the run needs each cycle, each of them mappable — and the cyclic traffic (the
run's PDOs, and those the drives keep sending) within the bitrate at the control rate (refused with the arithmetic and
the highest rate that fits)."""

from __future__ import annotations

import math

from rehabkit.canopen.bus.drive_dictionary import read_dictionary
from rehabkit.canopen.bus.pdo_layout import SENSOR_TPDO, BusLoad, needed, plans_load
from rehabkit.canopen.bus.pdo_plan import PdoPlan, PdoPlanError, entry, plan_pdos
from rehabkit.canopen.config import DRIVE_EDS, SENSOR_EDS, CanopenConfig, DriveSpec, SensorSpec
from rehabkit.canopen.drives.setup import unsupported_mode
from rehabkit.canopen.drives.units import UnitsError, declared_units
from rehabkit.core.kinds.errors import SettingError
from rehabkit.core.kinds.interfaces import Context

# what the backend writes by SDO, and so every drive must have: (index, subindex)
SET = ((0x1016, 1), (0x1017, 0), (0x6060, 0))
SENSOR_SET = ((0x1016, 1), (0x1017, 0), (0x2100, 0))


def drive_specs(config: CanopenConfig, dof: int) -> list[DriveSpec]:
    """The drives as written, or node ids 1..dof on the generic servo."""
    return list(config.drives) if config.drives is not None else [DriveSpec(node_id=i + 1) for i in range(dof)]


def sensor_specs(config: CanopenConfig, instruments: int) -> list[SensorSpec]:
    """The instruments' sensors as written, or node ids 64.. on the generic three-axis sensor."""
    return list(config.sensors) if config.sensors is not None else [
        SensorSpec(node_id=64 + k) for k in range(instruments)]


def _check_eds(config: CanopenConfig, spec: DriveSpec | SensorSpec, i: int, context: Context, period_s: float
               ) -> PdoPlan:
    """The node's EDS/DCF read as a master reads it (its PDOs, what can be mapped, its modes and units), and the PDOs
    the run would use on it; refused at the file's setting (or the mode's) where it cannot work."""
    sensor = isinstance(spec, SensorSpec)
    default = SENSOR_EDS if sensor else DRIVE_EDS
    path = context.resolve(spec.eds) if spec.eds is not None else default
    where = ("sensors" if sensor else "drives", i, "eds")
    if not path.is_file():
        raise SettingError(where, f"no such file: {path}")
    try:
        d = read_dictionary(path, spec.node_id)
    except Exception as exc:  # noqa: BLE001 (canopen's parser: whatever it refuses, said at the file's setting)
        raise SettingError(where, f"canopen cannot read {path.name} as an EDS/DCF: {exc}") from None
    if d.commissioned is not None and d.commissioned[0] != spec.node_id:
        node, line = d.commissioned
        raise SettingError(where, f"{path.name} is a DCF commissioned for node {node} ({path.name}:{line}: NodeID="
                           f"{node}): its PDOs' COB-IDs are node {node}'s, not node {spec.node_id}'s",
                           fix=f"give this drive node_id: {node}, or commission a DCF for node {spec.node_id}",
                           data={"commissioned": (node, line), "node_id": spec.node_id})
    missing = [f"0x{x:04X}" + (f"sub{s}" if s else "") for x, s in (SENSOR_SET if sensor else SET) if not d.has(x, s)]
    if missing:
        what = "a CiA 404 device's EDS" if sensor else "a CiA 402 drive's EDS"
        raise SettingError(where, f"{path.name} lacks objects the backend sets: {', '.join(missing)} (is it {what}?)")
    if sensor:
        rx, tx = [], [entry(d, x, s) for x, s, _ in SENSOR_TPDO]
    else:
        why = unsupported_mode(d.supported_modes, spec.mode)
        if why:
            raise SettingError(("drives", i, "mode"), f"{path.name}: {why}" + (
                "; a drive without any cannot be driven cycle by cycle: rehabkit runs drives in cyclic synchronous "
                "modes only" if "no cyclic" in why else ": set mode to one it has"))
        try:
            declared_units(spec.units(1.0), d)
        except UnitsError as exc:
            raise SettingError(where, f"{path.name}: {exc.what} ({d.where(exc.index)})") from None
        rx, tx = needed(d, spec.mode, config.torque_actual, spec.enable == "pdo")
    try:
        return plan_pdos(d, spec.node_id, rx, tx, period_s, config.other_pdos == "keep")
    except PdoPlanError as exc:
        fix = " (set enable: sdo: the controlword then goes by SDO)" if exc.index == 0x6040 else ""
        raise SettingError(where, f"{path.name}: {exc.what}{fix}") from None


def check_bus(config: CanopenConfig, context: Context) -> tuple[list[DriveSpec], list[SensorSpec], BusLoad]:
    """The drives for the run's robot, the sensors for its instruments, and the bus load; a :class:`SettingError`
    at the setting that is wrong."""
    robot = context.robot.model
    specs = drive_specs(config, robot.dof)
    if len(specs) != robot.dof:
        raise SettingError("drives", f"{len(specs)} drives for the {robot.dof} joints of robot '{robot.name}' "
                           f"({', '.join(robot.joint_names)}): one drive per joint, in that order")
    seen: dict[int, int] = {}
    plans: list[PdoPlan] = []
    for i, s in enumerate(specs):
        if s.node_id in seen:
            raise SettingError(("drives", i, "node_id"), f"node id {s.node_id} is drive {seen[s.node_id]}'s too: each "
                               "node on a bus has its own")
        if s.node_id == config.master_node_id:
            raise SettingError(("drives", i, "node_id"), f"node id {s.node_id} is the host's (master_node_id)")
        seen[s.node_id] = i
        plans.append(_check_eds(config, s, i, context, context.control_dt))
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
        plans.append(_check_eds(config, s, k, context, context.control_dt))
    _check_cob_ids(plans, specs, sensors)
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
    load = plans_load(plans, rate, config.bitrate, config.heartbeat_ms, len(specs), len(sensors))
    if load.load > 1.0:
        what = f"{len(specs)} drives" + (f" and {len(sensors)} sensors" if sensors else "")
        step = config.timestep if config.bus is None or config.bus.simulated else 1e-4
        raise SettingError(("rates", "control_hz"), f"the CAN bus cannot carry {what} at {rate:g} Hz: "
                           f"{load.describe()}", root=True, fix=f"set rates.control_hz: {_fitting(load, step)} (the "
                           f"highest rate that fits{_steps(step)}; the bus carries up to "
                           f"{math.floor(load.highest_rate_hz())} Hz), "
                           + ("turn off the drives' own PDOs the run does not use (backend.other_pdos: disable), "
                              if load.others_bits else "")
                           + (f"raise backend.bitrate (now {config.bitrate}; CAN's top: 1000000), "
                              if config.bitrate < 1_000_000 else "") + "or put fewer nodes on this bus",
                           data={"load": load})
    return specs, sensors, load


def _check_cob_ids(plans: list[PdoPlan], specs: list[DriveSpec], sensors: list[SensorSpec]) -> None:
    """No two PDOs on the bus with one COB-ID (a DCF written for one node id, given to another, says another's)."""
    owner: dict[int, tuple[int, str]] = {}
    nodes = [("drives", i, s.node_id) for i, s in enumerate(specs)] + [("sensors", k, s.node_id)
                                                                       for k, s in enumerate(sensors)]
    for k, (plan, (kind, i, node)) in enumerate(zip(plans, nodes, strict=True)):
        pdos = [(p.cob_id, p.slot.name) for p in (*plan.rx, *plan.tx)] + [(s.cob_id, s.name) for s, _ in plan.others]
        for cob, name in pdos:
            if cob in owner and owner[cob][0] != k:
                other = nodes[owner[cob][0]]
                raise SettingError((kind, i, "eds"), f"its {name} (node {node}) has COB-ID 0x{cob:03X}, as node "
                                   f"{other[2]}'s {owner[cob][1]} has: frames on a bus must not share one (a DCF "
                                   "is written for one node id: give each node its own)",
                                   data={"cob_id": cob, "pdo": name, "node": node, "other_node": other[2],
                                         "other_pdo": owner[cob][1]})
            owner[cob] = (k, name)


def _steps(step: float) -> str:
    return f" in whole {step * 1e3:g} ms steps of the simulated drives' plant" if step >= 1e-3 else ""


def _fitting(load: BusLoad, step: float) -> str:
    """The highest control rate the bus carries whose period is a whole number of ``step``s, written so that it
    passes as it is (166.6666667, a 6 ms period: '166.667' is a period 12 ns off the plant's step)."""
    k = max(1, math.ceil(1.0 / (load.highest_rate_hz() * step) - 1e-9))
    rate = 1.0 / (k * step)
    return f"{rate:g}" if abs(rate - round(rate)) < 1e-9 else f"{rate:.10g} (a period of {k * step * 1e3:g} ms)"
