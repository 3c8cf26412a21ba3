"""The canopen backend's settings (the ``backend:`` section of a scenario run on CiA 402 drives) and its faults."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pydantic import Field, computed_field

from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS
from rehabkit.core.kinds.interfaces import BackendFaultError, StrictModel
from rehabkit.models.strict import FilePath

DRIVE_EDS = Path(__file__).resolve().parent / "eds" / "cia402_servo.eds"  # rehabkit's generic servo (simulated)
SENSOR_EDS = Path(__file__).resolve().parent / "eds" / "cia404_sensor.eds"  # its generic three-axis sensor


@dataclass(frozen=True)
class DriveUnits:
    """A drive's units against its joint's: encoder counts per radian at the joint, the rated torque [N·m at the
    joint] its per mille values refer to, the direction (+1/-1) of its positive sense at the joint, the gear
    between (the drive's own rated torque 0x6076 is the motor's: the joint's over the gear ratio)."""

    counts_per_rad: float = 4096 / (2 * math.pi)
    rated_torque_nm: float = 10.0
    direction: int = 1
    gear_ratio: float = 1.0
    # what the drive declares (rehabkit.canopen.drives.units.declared_units); None: increments, increments/s, rpm
    position_per_rad: float | None = None
    velocity_per_rad_s: float | None = None
    accel_per_rad_s2: float | None = None
    motor_speed_per_rad_s: float | None = None
    velocity_unit: str = "position units/s"
    accel_unit: str = "position units/s/s"

    @property
    def position(self) -> float:
        """Position units (0x607A, 0x6064, 0x607D) per radian at the joint."""
        return self.position_per_rad or self.counts_per_rad

    @property
    def velocity(self) -> float:
        """Velocity units (0x60FF, 0x606C, 0x607F) per rad/s at the joint."""
        return self.velocity_per_rad_s or self.position

    @property
    def acceleration(self) -> float:
        """Acceleration units (0x6085) per rad/s² at the joint."""
        return self.accel_per_rad_s2 or self.velocity

    @property
    def motor_speed(self) -> float:
        """0x6080's unit (the motor's speed) per rad/s at the joint."""
        return self.motor_speed_per_rad_s or self.gear_ratio * 60.0 / (2 * math.pi)


class DriveFaultError(BackendFaultError):
    """A drive, or the bus, can no longer drive its joint: ``node`` (its node id, None for the bus), ``joint`` (its
    joint's name, or None), ``code`` (the CiA 301/402 error code, 0 where none applies), ``what`` (in words).
    ``observable``: the other drives still report their state, so the run watches its safety stop bring them to
    rest (not so when the whole bus is silent). ``setting``: the backend setting the fault is measured against
    (``backend.sdo_timeout_ms``), where one is, else empty; ``limit``: that setting's value (None where none).
    ``cause_code``: why, as a code (``emcy``, ``no-tpdo``, ``bus-silent``, ``heartbeat-lost``,
    ``left-operation-enabled``, ``not-operation-enabled``), where given; ``state``: the CiA 402 state the drive was
    in where that is why (``QUICK_STOP_ACTIVE``), else None."""

    def __init__(self, what: str, node: int | None = None, joint: str | None = None, code: int = 0,
                 observable: bool = True, setting: str = "", limit: float | None = None,
                 cause_code: str | None = None, state: str | None = None):
        self.what, self.node, self.joint, self.code = what, node, joint, code
        self.observable = observable  # (a silent bus reports nothing more to watch)
        self.setting, self.limit = setting, limit  # (the setting the words name, as fields)
        self.cause_code, self.state = cause_code, state  # (why as fields: the words say it too)
        where = f"drive {node} ({joint})" if node is not None else "the CAN bus"
        super().__init__(f"{where}: {what}")

    def event_data(self) -> dict | None:
        """``cause`` (its code) and, where they apply, the drive's ``node``, its ``error_code`` (CiA 301/402) and its
        ``state``, for the safety event's ``data``."""
        if self.cause_code is None:
            return None
        data: dict = {"cause": self.cause_code}
        if self.node is not None:
            data["node"] = self.node
        if self.code:
            data["error_code"] = self.code
        if self.state is not None:
            data["state"] = self.state
        return data


class Bus(StrictModel):
    """A CAN interface as python-can opens it (``can.Bus(interface=..., channel=..., bitrate=...)``)."""

    interface: str = Field(description="python-can interface: socketcan, pcan, kvaser, ixxat, udp_multicast, virtual")
    channel: str = Field(description="its channel: can0, PCAN_USBBUS1, 0, 239.74.163.2, ...")
    simulated: bool = Field(False, description="the drives on it are `rehabkit drives` simulations: each run "
                            "places their plant at its start posture (real drives start where the robot is)")


class DriveSpec(StrictModel):
    """One joint's drive: where it is on the bus, what it is, and its units against the joint's."""

    node_id: int = Field(ge=1, le=127, description="CANopen node id (1-127)")
    eds: FilePath | None = Field(None, description="the drive's EDS or DCF file (default: rehabkit's generic CiA "
                                 "402 servo, the simulated drives' own)")
    mode: Literal["cst", "csp", "csv"] = Field(
        "cst", description="operating mode: cst, cyclic synchronous torque (the controller's torques, the default); "
        "csp or csv, cyclic synchronous position or velocity: the drive closes its own loop on the plan's joint "
        "reference as the safety layer lets it through, the host adding gravity compensation as its torque offset "
        "(the controller's torques are then not sent: a stiff servo, for positioning, not for interaction)")
    gear_ratio: float = Field(1.0, gt=0, description="motor turns per joint turn")
    encoder_counts: int = Field(131072, gt=0, description="encoder counts per motor turn (the position unit)")
    rated_torque_nm: float | None = Field(None, gt=0, description="the motor's rated torque its per-mille torques "
                                          "refer to [N·m] (default: the drive's own, 0x6076, read at the start)")
    direction: Literal[1, -1] = Field(1, description="-1 where the drive's positive sense is the joint's negative")
    enable: Literal["pdo", "sdo"] = Field(
        "pdo", description="how the controlword goes: pdo, in the cyclic RPDO (the default); sdo, written by SDO "
        "whenever it changes (the walk to OPERATION ENABLED, the stop, the end), for a drive that does not take it "
        "in a PDO")

    def units(self, effort_nm: float) -> DriveUnits:
        """Its units at the joint, the joint's effort limit standing in for an unnamed rated torque (a simulated
        drive's; the master reads a drive's own, 0x6076, when the scenario names none)."""
        rated = self.rated_torque_nm or effort_nm / self.gear_ratio
        return DriveUnits(self.encoder_counts * self.gear_ratio / (2 * math.pi), rated * self.gear_ratio,
                          self.direction, self.gear_ratio)


class Injection(StrictModel):
    """A fault injected into the simulated drives for a safety-skill test or the fault table (never on a real bus)."""

    at_s: float = Field(gt=0, description="when [s of the run]")
    fault: Literal["drive", "drive-disabled", "drive-silent", "drive-heartbeat", "host-heartbeat", "host-stall",
                   "bus-off"] = Field(
        description="drive: the drive detects a fault (its EMCY, its reaction); drive-disabled: it leaves OPERATION "
        "ENABLED on its own, no fault (its enable input opened); drive-silent: it stops answering (no TPDO, no "
        "heartbeat); drive-heartbeat: its heartbeat stops, its PDOs go on; host-heartbeat: the host's heartbeat "
        "stops reaching the drives; host-stall: the host sends nothing for for_s (real time: no SYNC); bus-off: the "
        "host's CAN interface fails")
    for_s: float = Field(0.05, gt=0, description="how long a host-stall lasts [s]")
    node: int | None = Field(None, ge=1, le=127, description="the drive (default: the first)")
    code: int = Field(0x2310, ge=0, le=0xFFFF, description="the error code of a drive fault (default: over-current)")


class SensorSpec(StrictModel):
    """One of the run's instruments (a force-torque sensor's force, an accelerometer) on the bus: a three-axis
    measuring device (CiA 404)."""

    node_id: int = Field(ge=1, le=127, description="CANopen node id (1-127)")
    eds: FilePath | None = Field(None, description="its EDS (default: rehabkit's generic three-axis sensor: three "
                                 "INTEGER16 inputs at 0x7130 in units of 0x2100's scale)")


class CanopenConfig(StrictModel):
    """The drives on the CAN bus, the loop's clock and the bus's watchdogs."""

    bus: Bus | None = Field(None, description="the CAN interface of the robot's drives (none: simulated CiA 402 "
                            "drives on the robot's MuJoCo model, started with the run)")
    bitrate: Literal[10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000] = Field(
        1_000_000, description="the bus's bitrate [bit/s]: one of CiA 301's (10, 20, 50, 125, 250, 500, 800 kbit/s, "
        "1 Mbit/s)")
    drives: list[DriveSpec] | None = Field(None, description="one per joint, in the robot's joint order (default: "
                                           "node ids 1, 2, ... on the generic servo's EDS)")
    sensors: list[SensorSpec] | None = Field(None, description="one per instrument the run's sensors read, in their "
                                             "order (default: node ids 64, 65, ...)")
    clock: Literal["realtime", "lockstep"] = Field(
        "realtime", description="realtime: SYNC on the wall clock, as a robot's bus runs; lockstep: the simulated "
        "drives' plant advances one cycle per SYNC, in this process (deterministic, faster than real time)")
    timestep: float = Field(0.001, ge=0.0002, le=0.01, description="the simulated drives' plant step [s] (the "
                            "cycle is rates.control_hz's period)")
    robot_id: int = Field(1, ge=0, description="this robot among its kind (its e-stop latch: <robot>-<robot_id>)")
    master_node_id: int = Field(127, ge=1, le=127, description="the host's node id (its heartbeat's)")
    heartbeat_ms: int = Field(20, ge=1, le=65535, description="heartbeat period of the drives and the host [ms]")
    heartbeat_timeout_ms: int = Field(60, ge=1, le=65535, description="a heartbeat silent this long is lost: the "
                                      "drives fault on the host's, the host stops on a drive's [ms]")
    sync_timeout_ms: float = Field(SYNC_TIMEOUT_MS, gt=0, description="the simulated drives quick stop (EMCY 0x8100, "
                                   "as the run sets 0x6007) without a SYNC this long while powered, in real time [ms] "
                                   "(default: 3 cycles of 250 Hz + 20 ms, the worst stall of a process measured on a "
                                   "2-core VM: rehabkit.canopen.deadlines)")
    tpdo_timeout_ms: float = Field(50.0, gt=0, description="a drive whose TPDOs have not come for this long stops "
                                   "the run (a non-real-time host may answer a cycle late now and then) [ms]")
    sdo_timeout_ms: float = Field(1000.0, gt=0, description="how long the host waits for a drive's answer to each "
                                  "SDO request while it sets the drives up [ms] (python-canopen's own default, 300, "
                                  "was missed by simulated drives sharing a busy 2-core machine)")
    other_pdos: Literal["keep", "disable"] = Field(
        "keep", description="the drives' PDOs the run does not use: keep, as each drive has them (the ones it sends "
        "count in the bus load); disable, turned off at the set-up")
    end_nmt: Literal["pre-operational", "stopped"] = Field(
        "pre-operational", description="the NMT state the drives are left in when a run ends (after its stop, the "
        "power stages off): pre-operational (configurable by SDO, no PDOs) or stopped (NMT and heartbeat only)")
    torque_actual: bool = Field(False, description="map each drive's actual torque (0x6077) too (2 bytes a cycle "
                                "more each: see the bus load)")
    inject: list[Injection] = Field([], description="faults injected into the simulated drives (tests)")
    @computed_field
    @property
    def latch_prefix(self) -> str:
        """``sim-`` on simulated drives: a rehearsal latches ``sim-<robot>``, never the real robot's latch."""
        return "sim-" if self.simulated else ""

    @computed_field
    @property
    def latch_suffix(self) -> str:
        """``-<robot_id>`` on a robot's own drives (its latch ``<robot>-<robot_id>``)."""
        return "" if self.simulated else f"-{self.robot_id}"

    @property
    def simulated(self) -> bool:
        """The drives are simulations: this run's own, or ``rehabkit drives`` on the named bus."""
        return self.bus is None or self.bus.simulated

    trace: Literal["asc", "blf", "log", "none"] = Field(
        "asc", description="every frame into can.<trace> beside the run's log, by python-can's own writer (asc: "
        "Vector ASCII, blf: Vector binary, log: candump; the host's frames Tx, the nodes' Rx); none: no trace")
