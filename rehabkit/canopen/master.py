"""The host as CANopen master of a robot's CiA 402 drives: their set-up by SDO, the walk to OPERATION ENABLED, and
each cycle's RPDOs, SYNC and TPDOs, watched for what drives and buses do when things go wrong.

canopen (the library) does the protocol: SDO client, PDO maps written by SDO, NMT, SYNC, EMCY consumer. The 402
state machine is walked here, one controlword per cycle in the cyclic RPDO, reading the state back from the
statusword in the cyclic TPDO: canopen's ``BaseNode402`` waits on the wall clock for each state, which a lock-step
bus, where nothing moves between cycles, cannot give it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import can
import canopen
import numpy as np

from rehabkit.canopen.bus.pdo_codec import PdoCodec
from rehabkit.canopen.bus.pdo_layout import RPDO, SENSOR_TPDO, TPDO1, tpdo2
from rehabkit.canopen.bus.pdo_maps import write_maps
from rehabkit.canopen.cia402 import ENABLE_OPERATION_CMD, FAULT_RESET, SHUTDOWN, SWITCH_ON_CMD, State
from rehabkit.canopen.config import CanopenConfig, DriveFaultError, DriveUnits
from rehabkit.canopen.drive_limits import DriveLimits, fitted
from rehabkit.canopen.emcy_codes import describe

MODE_CODE = {"csp": 8, "csv": 9, "cst": 10}  # modes of operation (0x6060): cyclic synchronous position/velocity/torque
DISABLE_VOLTAGE_CW = 0x00


def interpolation_period(period_s: float) -> tuple[int, int]:
    """0x60C2: the cycle as value × 10^index s (value 0-255, index -3 to -6)."""
    for index in range(-3, -7, -1):
        value = period_s / 10.0**index
        if abs(value - round(value)) < 1e-6 and round(value) <= 255:
            return round(value), index
    raise ValueError(f"a cycle of {period_s:g} s is no whole number of microseconds up to 255")


class DriveMaster:
    """Drives ``nodes`` (node ids, each with its EDS and units) of joints ``names`` on ``network``; ``now()`` is the
    master's clock [s] (a lock-step bus: its cycles)."""

    def __init__(self, network: canopen.Network, nodes: Sequence[tuple[int, str]], units: Sequence[DriveUnits],
                 names: Sequence[str], config: CanopenConfig, now: Callable[[], float],
                 read_rated: Sequence[bool] = (), sensors: Sequence[tuple[int, str, str]] = (),
                 modes: Sequence[str] = ()):
        self.network, self.config, self.now = network, config, now
        self.units = list(units)
        self._read_rated = list(read_rated) or [False] * len(self.units)
        self.modes = list(modes) or ["cst"] * len(self.units)
        self._follows = np.array([m != "cst" for m in self.modes])
        self._by_velocity = np.array([m == "csv" for m in self.modes])
        self.remotes = [canopen.RemoteNode(node, eds) for node, eds in nodes]
        self.sensors = [canopen.RemoteNode(node, eds) for node, eds, _ in sensors]  # (three-axis: CiA 404)
        for r in (*self.remotes, *self.sensors):
            network.add_node(r)
        n, m = len(self.remotes), len(self.sensors)
        # every node: the drives (joint i), then the sensors (instrument k at n + k)
        self.ids = [r.id for r in (*self.remotes, *self.sensors)]
        self.names = [*names, *(name for _, _, name in sensors)]
        self.readings = np.zeros((m, 3))  # each sensor's newest values [its unit: N, m/s²]
        self._sensor_scale = np.ones(m)
        self.status = np.zeros(n, int)
        self.counts = np.zeros((3, n))  # position, velocity, torque actual (drive units) of the newest TPDOs
        self.q, self.qd, self.applied = np.zeros(n), np.zeros(n), np.zeros(n)
        self._scale = np.array([u.counts_per_rad * u.direction for u in units])
        self._per_mille = np.array([1e3 * u.direction / u.rated_torque_nm for u in units])
        self._got = np.zeros(n + m, bool)
        self.missed = np.zeros(n + m, int)  # cycles in a row each node's TPDOs did not come
        self.missed_total = 0
        self._arrived = threading.Event()
        self.emcys: list[tuple[float, int, int]] = []  # (time, node, code) of each EMCY, in order
        self._emcy_new: list[tuple[int, int]] = []
        self.heard = np.zeros(n + m)  # when each node's heartbeat came last [s, master clock]
        self.enabled = False
        self.beating = True  # (False: an injected fault, the host's heartbeat stops)
        self.cycles = 0
        self._next_beat = 0.0
        self.controlword = np.full(n, SHUTDOWN, int)
        self._rpdo: list[PdoCodec | None] = [None] * n
        self._tpdo: dict[int, tuple[int, int, object]] = {}  # COB-ID → (node, TPDO number, its layout)
        self.states: list[str] = [State.NOT_READY_TO_SWITCH_ON.name] * n

    # -- set-up ---------------------------------------------------------------------------------------------

    def wait_for_nodes(self, timeout_s: float = 10.0) -> None:
        """Every node answering an SDO (its device type, 0x1000), within ``timeout_s`` of wall time: drives on a bus
        powered up a moment ago, or ``rehabkit drives`` started just before the run, are given the time to boot."""
        deadline = time.monotonic() + timeout_s
        for r, name in zip((*self.remotes, *self.sensors), self.names, strict=True):
            while True:
                try:
                    r.sdo.upload(0x1000, 0)
                    break
                except canopen.SdoCommunicationError:
                    if time.monotonic() > deadline:
                        raise DriveFaultError(f"does not answer on the bus within {timeout_s:g} s (is it powered, "
                                              "its node id and bitrate as the scenario says; simulated: is `rehabkit "
                                              "drives` running on this interface and channel?)", r.id, name,
                                              observable=False) from None

    def configure(self, period_s: float, limits: DriveLimits) -> list[str]:
        """By SDO, in pre-operational: the cycle, heartbeats, CST, each drive's limits and PDO maps; then NMT start.
        Returns what it had to say: a limit more than its object holds, told the largest it holds."""
        notes: list[str] = []
        self.wait_for_nodes()
        cfg = self.config
        value, index = interpolation_period(period_s)
        self.missed_limit = max(1, math.ceil(cfg.tpdo_timeout_ms * 1e-3 / period_s - 1e-9))
        for i, r in enumerate(self.remotes):
            self._communication(r, period_s)
            if self._read_rated[i]:  # the drive's own rated torque (the motor's [mN·m]), at the joint
                u = self.units[i]
                self.units[i] = replace(u, rated_torque_nm=r.sdo[0x6076].raw * 1e-3 * u.gear_ratio)
                self._per_mille[i] = 1e3 * u.direction / self.units[i].rated_torque_nm
            sd, u = r.sdo, self.units[i]
            sd[0x6060].raw = MODE_CODE[self.modes[i]]
            sd[0x60C2][1].raw, sd[0x60C2][2].raw = value, index
            lo, hi = sorted((limits.lower[i] * self._scale[i], limits.upper[i] * self._scale[i]))
            od = r.object_dictionary[0x607D]
            sd[0x607D][1].raw, sd[0x607D][2].raw = fitted(od[1], lo, down=True)[0], fitted(od[2], hi)[0]
            sd[0x6072].raw = min(65535, math.ceil(limits.torque[i] / u.rated_torque_nm * 1e3))
            for obj, bound, what, unit in ((0x6080, limits.speed[i], "speed limit", "rad/s"),
                                           (0x6085, limits.decel[i], "quick stop deceleration", "rad/s²")):
                raw, clipped = fitted(r.object_dictionary[obj], bound * u.counts_per_rad)
                sd[obj].raw = raw
                if clipped:
                    notes.append(f"drive {r.id} ({self.names[i]}): its {what}, {bound:.4g} {unit}, is more counts "
                                 f"than 0x{obj:04X} holds at {u.counts_per_rad:.4g} counts/rad: told its largest, "
                                 f"{raw / u.counts_per_rad:.4g} {unit}")
            sd[0x605A].raw = limits.quick_stop_option
            if 0x6007 in r.object_dictionary:  # (optional in the profile)
                sd[0x6007].raw = limits.abort_option
            rx, tx = write_maps(self.network, r, [RPDO[self.modes[i]]], [TPDO1, tpdo2(cfg.torque_actual)])
            self._rpdo[i] = rx[0]
            self._listen(tx, i)
        n = len(self.remotes)
        for k, r in enumerate(self.sensors):
            self._communication(r, period_s)
            self._sensor_scale[k] = float(r.sdo[0x2100].raw)
            _, tx = write_maps(self.network, r, [], [SENSOR_TPDO])
            self._listen(tx, n + k)
        for r in (*self.remotes, *self.sensors):
            r.nmt.state = "OPERATIONAL"
        self.heard[:] = self.now()
        return notes

    def _communication(self, r: canopen.RemoteNode, period_s: float) -> None:
        """A node in pre-operational: its cycle, its heartbeat and the host's it watches, its EMCYs and heartbeats
        heard here."""
        cfg = self.config
        r.nmt.state = "PRE-OPERATIONAL"
        r.sdo[0x1006].raw = round(period_s * 1e6)
        r.sdo[0x1017].raw = cfg.heartbeat_ms
        r.sdo[0x1016][1].raw = cfg.master_node_id << 16 | cfg.heartbeat_timeout_ms
        r.emcy.add_callback(lambda err, node=r.id: self._emcy_new.append((node, err.code)))
        self.network.subscribe(0x700 + r.id, self._on_heartbeat)

    def _listen(self, tpdos: list[PdoCodec], i: int) -> None:
        for number, codec in enumerate(tpdos, start=1):
            self._tpdo[codec.cob_id] = (i, number, codec.layout)
            self.network.subscribe(codec.cob_id, self._on_tpdo)

    def _on_tpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        i, number, layout = self._tpdo[can_id]
        values = layout.unpack_from(data)
        n = len(self.remotes)
        if i >= n:  # a sensor's three inputs
            self.readings[i - n] = np.array(values) * self._sensor_scale[i - n]
        elif number == 1:
            self.status[i], self.counts[0, i] = values
            return
        else:
            self.counts[1, i] = values[0]  # (the last of a drive's cycle)
            if len(values) > 1:
                self.counts[2, i] = values[1]
        self._got[i] = True
        if self._got.all():
            self._arrived.set()

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.heard[self.ids.index(can_id - 0x700)] = self.now()

    def place(self, q0: np.ndarray) -> None:
        """Simulated drives only: their plant reset to ``q0`` (the simulation's own objects 0x2000, 0x2001)."""
        for r, scale, q in zip(self.remotes, self._scale, q0, strict=True):
            r.sdo[0x2000].raw = round(q * scale)
        self.remotes[0].sdo[0x2001].raw = 1

    # -- cycles ---------------------------------------------------------------------------------------------

    def enable(self, cycle: Callable[[np.ndarray], object], fault_reset: bool = False) -> None:
        """The 402 walk to OPERATION ENABLED, one controlword a cycle (``cycle``: one, paced as the run paces
        them), zero torque (a fault reset first only when a person has cleared the latch: ``fault_reset``)."""
        zero = np.zeros(len(self.remotes))
        if fault_reset:
            self.controlword[:] = FAULT_RESET
            cycle(zero)
        # from wherever the last run left them (a quick stop held: QUICK STOP ACTIVE) to SWITCH ON DISABLED first
        for word in (DISABLE_VOLTAGE_CW, SHUTDOWN, SWITCH_ON_CMD, ENABLE_OPERATION_CMD, ENABLE_OPERATION_CMD):
            self.controlword[:] = word
            cycle(zero)
        for i, s in enumerate(self.states):
            if s != State.OPERATION_ENABLED.name:
                code = self.remotes[i].sdo[0x603F].raw
                raise DriveFaultError(f"did not reach OPERATION ENABLED: {s}" + (
                    f" ({describe(code)}); a drive's fault is reset only once a person has cleared the robot's "
                    "e-stop latch" if s == State.FAULT.name else ""), self.remotes[i].id, self.names[i], code)
        self.enabled = True

    def cycle(self, tau: np.ndarray, wait_s: float = 0.0, q: np.ndarray | None = None,
              qd: np.ndarray | None = None) -> float:
        """RPDOs with ``tau`` [N·m], the heartbeat when due, SYNC, the TPDOs in (real time: up to ``wait_s``); the
        joint state read. Returns the wall time from SYNC to the last TPDO [s] (nan if one did not come)."""
        targets = np.clip(np.rint(tau * self._per_mille), -32768, 32767)  # (CSP/CSV: the torque offset)
        if q is not None and self._follows.any():  # their position or velocity targets [counts, counts/s]
            setpoints = np.clip(np.rint(np.where(self._by_velocity, qd, q) * self._scale), -2**31, 2**31 - 1)
        else:  # (no targets: the set-up's and the close's cycles) where they are, at rest
            setpoints = np.where(self._by_velocity, 0.0, np.rint(self.q * self._scale))
        self._got[:] = False
        self._arrived.clear()
        try:
            for codec, follows, cw, target, point in zip(self._rpdo, self._follows, self.controlword, targets,
                                                         setpoints, strict=True):
                values = (int(cw), int(point), int(target)) if follows else (int(cw), int(target))
                self.network.send_message(codec.cob_id, codec.layout.pack(*values))
            if self.now() >= self._next_beat and self.beating:
                self._next_beat += self.config.heartbeat_ms * 1e-3
                self.network.send_message(0x700 + self.config.master_node_id, b"\x05")
            sent = time.perf_counter()
            self.network.sync.transmit()
        except can.CanError as exc:
            raise DriveFaultError(f"sending failed, the bus is down ({exc})", observable=False) from exc
        arrived = self._got.all() or self._arrived.wait(wait_s)
        latency = time.perf_counter() - sent if arrived else math.nan
        self.cycles += 1
        seen = self._got.copy()
        self.missed[seen] = 0
        self.missed[~seen] += 1
        self.missed_total += int((~seen).sum())
        got = seen[: len(self.remotes)]
        self.q[got] = self.counts[0, got] / self._scale[got]
        self.qd[got] = self.counts[1, got] / self._scale[got]
        self.applied[got] = self.counts[2, got] / self._per_mille[got]
        self.states = [State.of(int(s)).name for s in self.status]
        return latency

    def fault(self) -> DriveFaultError | None:
        """What went wrong since the last cycle, if anything (the first thing: one stop, one reason)."""
        now = self.now()
        while self._emcy_new:
            node, code = self._emcy_new.pop(0)
            self.emcys.append((now, node, code))
            if code:  # (0: the error reset)
                return DriveFaultError(f"EMCY: {describe(code)}", node, self.names[self.ids.index(node)], code)
        late = np.flatnonzero(self.missed >= self.missed_limit)
        if len(late) == len(self.ids):
            return DriveFaultError(f"no TPDO from any node for {self.missed_limit} cycles: the bus is silent",
                                   observable=False)
        if len(late):
            i = int(late[0])
            return DriveFaultError(f"no TPDO for {self.missed[i]} cycles ({self.config.tpdo_timeout_ms:g} ms)",
                                   self.ids[i], self.names[i])
        silent = np.flatnonzero(now - self.heard > self.config.heartbeat_timeout_ms * 1e-3)
        if len(silent):
            i = int(silent[0])
            return DriveFaultError(f"its heartbeat is lost (silent {1e3 * (now - self.heard[i]):.0f} ms > "
                                   f"{self.config.heartbeat_timeout_ms} ms: {describe(0x8130)})", self.ids[i],
                                   self.names[i], 0x8130)
        if self.enabled:
            for i, s in enumerate(self.states):
                if s != State.OPERATION_ENABLED.name and self.controlword[i] == ENABLE_OPERATION_CMD:
                    return DriveFaultError(f"left OPERATION ENABLED: now {s}", self.remotes[i].id, self.names[i])
        return None

    def torque_off(self) -> None:
        """From the next cycle on every drive's power stage off (disable voltage)."""
        self.controlword[:] = DISABLE_VOLTAGE_CW
