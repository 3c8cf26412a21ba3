"""The host as CANopen master of a robot's CiA 402 drives: their set-up by SDO, the walk to OPERATION ENABLED, and
each cycle's RPDOs, SYNC and TPDOs, watched for what drives and buses do when things go wrong.

canopen (the library) does the protocol: SDO client, PDO maps written by SDO, NMT, SYNC, EMCY consumer. The 402
state machine is walked here, one controlword per cycle in the cyclic RPDO, reading the state back from the
statusword in the cyclic TPDO: canopen's ``BaseNode402`` waits on the wall clock for each state, which a lock-step
bus, where nothing moves between cycles, cannot give it.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections.abc import Callable, Sequence

import can
import canopen
import numpy as np

from rehabkit.canopen.bus.drive_dictionary import from_od, object_dictionary
from rehabkit.canopen.bus.pdo_codec import PdoCodec
from rehabkit.canopen.bus.pdo_layout import SENSOR_TPDO
from rehabkit.canopen.bus.pdo_maps import write_plan
from rehabkit.canopen.bus.pdo_plan import entry, plan_pdos
from rehabkit.canopen.cia402 import DISABLE_VOLTAGE, ENABLE_OPERATION_CMD, FAULT_RESET, SHUTDOWN, SWITCH_ON_CMD, State
from rehabkit.canopen.config import CanopenConfig, DriveFaultError, DriveUnits
from rehabkit.canopen.drives.limits import DriveLimits
from rehabkit.canopen.drives.setup import set_up_drive
from rehabkit.canopen.emcy_codes import describe

# the process data's (index, subindex), as each node's newest TPDOs and the cycle's RPDOs carry them
CONTROLWORD, TORQUE, OFFSET, POSITION, VELOCITY = (0x6040, 0), (0x6071, 0), (0x60B2, 0), (0x607A, 0), (0x60FF, 0)
STATUSWORD, POSITION_ACTUAL, VELOCITY_ACTUAL, TORQUE_ACTUAL_KEY = (0x6041, 0), (0x6064, 0), (0x606C, 0), (0x6077, 0)
SENSOR_KEYS = tuple((index, sub) for index, sub, _ in SENSOR_TPDO)  # a three-axis sensor's inputs (CiA 404)
LIVE_KEYS = (STATUSWORD, POSITION_ACTUAL, VELOCITY_ACTUAL, TORQUE_ACTUAL_KEY, *SENSOR_KEYS)


class DriveMaster:
    """Drives ``nodes`` (node ids, each with its EDS and units) of joints ``names`` on ``network``; ``now()`` is the
    master's clock [s] (a lock-step bus: its cycles)."""

    def __init__(self, network: canopen.Network, nodes: Sequence[tuple[int, str]], units: Sequence[DriveUnits],
                 names: Sequence[str], config: CanopenConfig, now: Callable[[], float],
                 read_rated: Sequence[bool] = (), sensors: Sequence[tuple[int, str, str]] = (),
                 modes: Sequence[str] = (), enable_by: Sequence[str] = ()):
        self.network, self.config, self.now = network, config, now
        self.units = list(units)
        self._read_rated = list(read_rated) or [False] * len(self.units)
        self.modes = list(modes) or ["cst"] * len(self.units)
        self.by_pdo = [e != "sdo" for e in enable_by] or [True] * len(self.units)
        self._follows = np.array([m != "cst" for m in self.modes])
        self._by_velocity = np.array([m == "csv" for m in self.modes])
        self.paths = [eds for _, eds in nodes]
        self.remotes = [canopen.RemoteNode(node, object_dictionary(eds, node)) for node, eds in nodes]
        self.sensors = [canopen.RemoteNode(node, object_dictionary(eds, node))  # (three-axis: CiA 404)
                        for node, eds, _ in sensors]
        for r in (*self.remotes, *self.sensors):
            network.add_node(r)
            r.sdo.RESPONSE_TIMEOUT = config.sdo_timeout_ms * 1e-3  # (python-canopen's SdoClient setting: its wait)
        n, m = len(self.remotes), len(self.sensors)
        # every node: the drives (joint i), then the sensors (instrument k at n + k)
        self.ids = [r.id for r in (*self.remotes, *self.sensors)]
        self.names = [*names, *(name for _, _, name in sensors)]
        self.readings = np.zeros((m, 3))  # each sensor's newest values [its unit: N, m/s²]
        self._sensor_scale = np.ones(m)
        self.status = np.zeros(n, int)
        self.q, self.qd, self.applied = np.zeros(n), np.zeros(n), np.zeros(n)
        self._scale = np.array([u.position * u.direction for u in units])  # position units per rad (signed)
        self._vscale = np.array([u.velocity * u.direction for u in units])  # velocity units per rad/s (signed)
        self._per_mille = np.array([1e3 * u.direction / u.rated_torque_nm for u in units])
        self._live: list[dict[tuple[int, int], int]] = [dict.fromkeys(LIVE_KEYS, 0) for _ in range(n + m)]
        self._mask, self._expect = [0] * (n + m), [0] * (n + m)  # each node's TPDOs in this cycle / all of them
        self._got = np.zeros(n + m, bool)
        self.missed = np.zeros(n + m, int)  # cycles in a row each node's TPDOs did not come
        self.missed_total = 0
        self._arrived = threading.Event()
        self.emcys: list[tuple[float, int, int]] = []  # (time, node, code) of each EMCY, in order
        self._emcy_new: list[tuple[int, int]] = []
        self._heeded: set[int] = set()
        self.heard = np.zeros(n + m)  # when each node's heartbeat came last [s, master clock]
        self.enabled = False
        self.beating = True  # (False: an injected fault, the host's heartbeat stops)
        self.cycles = 0
        self._next_beat = 0.0
        self.controlword = np.full(n, SHUTDOWN, int)
        self._sent_cw = np.full(n, -1, int)  # the controlword last written by SDO (drives enabled by SDO)
        self._rpdo: list[list[PdoCodec]] = [[] for _ in range(n)]
        self._out: dict[tuple[int, int], int] = {}  # a cycle's RPDO values, one drive at a time
        self._tpdo: dict[int, tuple[int, PdoCodec, int]] = {}  # COB-ID → (node, its codec, its bit in the mask)
        self.plans: list = []
        self.setup_notes: list[str] = []
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
                except canopen.SdoAbortedError:  # (it answered: there, if without a device type to give)
                    break
                except canopen.SdoCommunicationError:
                    if time.monotonic() > deadline:
                        raise DriveFaultError(f"does not answer on the bus within {timeout_s:g} s (is it powered, "
                                              "its node id and bitrate as the scenario says; simulated: is `rehabkit "
                                              "drives` running on this interface and channel?)", r.id, name,
                                              observable=False) from None

    def configure(self, period_s: float, limits: DriveLimits) -> list[str]:
        """By SDO, in pre-operational: the cycle, heartbeats, each drive set up from what it says it has (its mode,
        limits in its units, the PDOs the run needs: :func:`~rehabkit.canopen.drives.setup.set_up_drive`); then NMT
        start. Returns what it had to say (a limit more than its object holds, told the largest it holds)."""
        notes = self.setup_notes = []
        self.wait_for_nodes()
        cfg = self.config
        self.missed_limit = max(1, math.ceil(cfg.tpdo_timeout_ms * 1e-3 / period_s - 1e-9))
        self.plans = []
        for i, r in enumerate(self.remotes):
            try:
                self._communication(r, period_s)
                setup = set_up_drive(r, self.paths[i], self.names[i], self.units[i], self.modes[i], limits, i,
                                     period_s, cfg.torque_actual, self._read_rated[i], self.by_pdo[i],
                                     cfg.other_pdos == "keep")
            except canopen.SdoCommunicationError:  # (it answered a moment ago: the bus or the drive stalled)
                raise DriveFaultError(f"stopped answering SDO requests while it was set up (none within "
                                      f"{cfg.sdo_timeout_ms:g} ms: backend.sdo_timeout_ms)", r.id, self.names[i],
                                      observable=False, setting="backend.sdo_timeout_ms",
                                      limit=cfg.sdo_timeout_ms) from None
            self.units[i] = u = setup.units
            self._scale[i] = u.position * u.direction
            self._vscale[i] = u.velocity * u.direction
            self._per_mille[i] = 1e3 * u.direction / u.rated_torque_nm
            notes += setup.notes
            self.plans.append(setup.plan)
            rx, tx = write_plan(self.network, r, setup.plan)
            self._rpdo[i] = rx
            self._listen(tx, i)
        n = len(self.remotes)
        for k, r in enumerate(self.sensors):
            self._communication(r, period_s)
            self._sensor_scale[k] = float(r.sdo[0x2100].raw)
            d = from_od(r.object_dictionary)
            plan = plan_pdos(d, r.id, [], [entry(d, *key) for key in SENSOR_KEYS], period_s)
            self.plans.append(plan)
            _, tx = write_plan(self.network, r, plan)
            self._listen(tx, n + k)
        for r in (*self.remotes, *self.sensors):
            r.nmt.state = "OPERATIONAL"
        self.heard[:] = self.now()
        return notes

    def _communication(self, r: canopen.RemoteNode, period_s: float) -> None:
        """A node in pre-operational: its cycle (0x1006, where it has one: many drives take the SYNCs as they come),
        its heartbeat and the host's it watches, its EMCYs and heartbeats heard here."""
        cfg = self.config
        r.nmt.state = "PRE-OPERATIONAL"
        if 0x1006 in r.object_dictionary:
            r.sdo[0x1006].raw = round(period_s * 1e6)
        r.sdo[0x1017].raw = cfg.heartbeat_ms
        if r.id not in self._heeded:  # (a second configure, after a reset of the node, adds no second callback)
            self._heeded.add(r.id)
            r.emcy.add_callback(lambda err, node=r.id: self._emcy_new.append((node, err.code)))
            self.network.subscribe(0x700 + r.id, self._on_heartbeat)

    def watch_host(self) -> list[str]:
        """Each node told to watch the host's heartbeat (0x1016 sub 1), just before the walk enables the drives:
        the host beats every cycle from then on, whatever the loop does (set up earlier, a drive activated by the
        reset's first heartbeat lost it while the run made its first plan: EMCY 0x8130 at t = 0). Returns what it
        had to say: a node that does not take the entry."""
        cfg, said = self.config, []
        entry = cfg.master_node_id << 16 | cfg.heartbeat_timeout_ms
        for r in (*self.remotes, *self.sensors):
            try:
                r.sdo[0x1016][1].raw = entry
            except canopen.SdoAbortedError as exc:  # (an EDS whose limits say it cannot: Elmo's caps it at 65535)
                said.append(f"node {r.id}: it does not take the host's heartbeat to watch (0x1016sub1 = "
                            f"0x{entry:08X}: SDO abort 0x{exc.code:08X}): the host's silence reaches it as its SYNC "
                            "stopping only")
        self._next_beat = self.now()  # (the first heartbeat with the walk's first cycle: the watch starts there)
        return said

    def _listen(self, tpdos: list[PdoCodec], i: int) -> None:
        self._expect[i] = (1 << len(tpdos)) - 1
        for k, codec in enumerate(tpdos):
            self._tpdo[codec.cob_id] = (i, codec, 1 << k)
            self.network.subscribe(codec.cob_id, self._on_tpdo)

    def _on_tpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        i, codec, bit = self._tpdo[can_id]
        codec.unpack_into(data, self._live[i])
        self._mask[i] |= bit
        if self._mask[i] == self._expect[i]:
            self._got[i] = True
            if self._got.all():
                self._arrived.set()

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.heard[self.ids.index(can_id - 0x700)] = self.now()

    def place(self, q0: np.ndarray) -> None:
        """Simulated drives only: their plant reset to ``q0`` (the simulation's own objects 0x5FFE, the start
        position, and 0x5FFF, place: raw downloads, since a vendor's EDS the master reads has neither)."""
        for r, scale, q in zip(self.remotes, self._scale, q0, strict=True):
            r.sdo.download(0x5FFE, 0, struct.pack("<i", round(q * scale)))
        self.remotes[0].sdo.download(0x5FFF, 0, b"\x01")

    # -- cycles ---------------------------------------------------------------------------------------------

    def enable(self, cycle: Callable[[np.ndarray], object], fault_reset: bool = False, patience: int = 5) -> None:
        """The 402 walk to OPERATION ENABLED, one controlword a cycle (``cycle``: one, paced as the run paces
        them), zero torque (a fault reset first only when a person has cleared the latch: ``fault_reset``). Each
        word is held until every drive reports the state it leads to, up to ``patience`` cycles more (a drive in
        another process, or a loaded bus, may answer a cycle or two late)."""
        zero = np.zeros(len(self.remotes))
        if fault_reset:
            self.controlword[:] = FAULT_RESET
            cycle(zero)
        # from wherever the last run left them (a quick stop held: QUICK STOP ACTIVE) to SWITCH ON DISABLED first
        walk = ((DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED), (SHUTDOWN, State.READY_TO_SWITCH_ON),
                (SWITCH_ON_CMD, State.SWITCHED_ON), (ENABLE_OPERATION_CMD, State.OPERATION_ENABLED))
        for word, state in walk:
            self.controlword[:] = word
            cycle(zero)
            for _ in range(patience):
                if all(s == state.name for s in self.states) or State.FAULT.name in self.states:
                    break
                cycle(zero)
        for i, s in enumerate(self.states):
            if s != State.OPERATION_ENABLED.name:
                code = self.remotes[i].sdo[0x603F].raw
                raise DriveFaultError(f"did not reach OPERATION ENABLED: {s}" + (
                    f" ({describe(code)}); a drive's fault is reset only once a person has cleared the robot's "
                    "e-stop latch" if s == State.FAULT.name else ""), self.remotes[i].id, self.names[i], code,
                    cause_code="not-operation-enabled", state=s)
        self.enabled = True

    def cycle(self, tau: np.ndarray, wait_s: float = 0.0, q: np.ndarray | None = None,
              qd: np.ndarray | None = None) -> float:
        """RPDOs with ``tau`` [N·m], the heartbeat when due, SYNC, the TPDOs in (real time: up to ``wait_s``); the
        joint state read. Returns the wall time from SYNC to the last TPDO [s] (nan if one did not come)."""
        targets = np.clip(np.rint(tau * self._per_mille), -32768, 32767)  # (CSP/CSV: the torque offset)
        if q is not None and self._follows.any():  # their position or velocity targets [their units]
            setpoints = np.clip(np.rint(np.where(self._by_velocity, qd * self._vscale, q * self._scale)), -2**31,
                                2**31 - 1)
        else:  # (no targets: the set-up's and the close's cycles) where they are, at rest
            setpoints = np.where(self._by_velocity, 0.0, np.rint(self.q * self._scale))
        self._got[:] = False
        self._mask[:] = [0] * len(self._mask)
        self._arrived.clear()
        try:
            self._controlwords_by_sdo()
            out = self._out  # (each RPDO's codec packs the objects its map carries)
            for codecs, cw, target, point in zip(self._rpdo, self.controlword, targets, setpoints, strict=True):
                out[CONTROLWORD], out[TORQUE] = int(cw), int(target)
                out[OFFSET], out[POSITION] = out[TORQUE], int(point)  # (CSP/CSV: the torque offset, the setpoint)
                out[VELOCITY] = out[POSITION]
                for codec in codecs:
                    self.network.send_message(codec.cob_id, codec.pack(out))
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
        n = len(self.remotes)
        for i in np.flatnonzero(seen[:n]):
            live = self._live[i]
            self.status[i] = live[STATUSWORD]
            self.q[i] = live[POSITION_ACTUAL] / self._scale[i]
            self.qd[i] = live[VELOCITY_ACTUAL] / self._vscale[i]
            self.applied[i] = live[TORQUE_ACTUAL_KEY] / self._per_mille[i]
        for k in np.flatnonzero(seen[n:]):
            live = self._live[n + k]
            self.readings[k] = np.array([live[key] for key in SENSOR_KEYS]) * self._sensor_scale[k]
        self.states = [State.of(int(s)).name for s in self.status]
        return latency

    def _controlwords_by_sdo(self) -> None:
        """Drives enabled by SDO: a controlword that changed written before the cycle's RPDOs."""
        for i, by_pdo in enumerate(self.by_pdo):
            if not by_pdo and self.controlword[i] != self._sent_cw[i]:
                try:
                    self.remotes[i].sdo[0x6040].raw = int(self.controlword[i])
                except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as exc:
                    raise DriveFaultError(f"its controlword could not be written by SDO ({exc})", self.remotes[i].id,
                                          self.names[i]) from exc
                self._sent_cw[i] = self.controlword[i]

    def fault(self) -> DriveFaultError | None:
        """What went wrong since the last cycle, if anything (the first thing: one stop, one reason)."""
        now = self.now()
        while self._emcy_new:
            node, code = self._emcy_new.pop(0)
            self.emcys.append((now, node, code))
            if code:  # (0: the error reset)
                return DriveFaultError(f"EMCY: {describe(code)}", node, self.names[self.ids.index(node)], code,
                                       cause_code="emcy")
        late = np.flatnonzero(self.missed >= self.missed_limit)
        if len(late) == len(self.ids):
            return DriveFaultError(f"no TPDO from any node for {self.missed_limit} cycles: the bus is silent",
                                   observable=False, cause_code="bus-silent")
        if len(late):
            i = int(late[0])
            return DriveFaultError(f"no TPDO for {self.missed[i]} cycles ({self.config.tpdo_timeout_ms:g} ms)",
                                   self.ids[i], self.names[i], cause_code="no-tpdo")
        silent = np.flatnonzero(now - self.heard > self.config.heartbeat_timeout_ms * 1e-3)
        if len(silent):
            i = int(silent[0])
            return DriveFaultError(f"its heartbeat is lost (silent {1e3 * (now - self.heard[i]):.0f} ms > "
                                   f"{self.config.heartbeat_timeout_ms} ms: {describe(0x8130)})", self.ids[i],
                                   self.names[i], 0x8130, cause_code="heartbeat-lost")
        if self.enabled:
            for i, s in enumerate(self.states):
                if s != State.OPERATION_ENABLED.name and self.controlword[i] == ENABLE_OPERATION_CMD:
                    return DriveFaultError(f"left OPERATION ENABLED: now {s}", self.remotes[i].id, self.names[i],
                                           cause_code="left-operation-enabled", state=s)
        return None

    def torque_off(self) -> None:
        """From the next cycle on every drive's power stage off (disable voltage)."""
        self.controlword[:] = DISABLE_VOLTAGE
