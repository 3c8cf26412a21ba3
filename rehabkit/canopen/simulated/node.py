"""What every simulated CANopen device of rehabkit's is besides its own job: a CiA 301 device serving its EDS or DCF
(:mod:`~rehabkit.canopen.simulated.device`: SDO server and its checks; :mod:`~rehabkit.canopen.simulated.nmt_slave`:
boot-up, NMT, heartbeat; :mod:`~rehabkit.canopen.simulated.errors`: 0x1001, 0x1003, EMCY;
:mod:`~rehabkit.canopen.simulated.watchdogs`: the heartbeat consumer), with its process data and PDOs.

- Its values (``values``: every (index, subindex) it acts on or produces) are served to SDO reads as they stand and
  taken from SDO writes and RPDOs; one its EDS lacks keeps an internal default and is not served (a master sees the
  device as its EDS says).
- The PDO maps are whatever a master wrote within CiA 301's rules, else the EDS's own (COB-IDs with the node id),
  read as it enters OPERATIONAL or at the first SYNC after they change; each in one ``struct``
  (:mod:`~rehabkit.canopen.bus.pdo_codec`). A synchronous RPDO's values are taken at the next SYNC, an event-driven
  one's at once; enabled TPDOs go out at the SYNC (synchronous: every n-th; event-driven: when their data changed).
  PDOs only in OPERATIONAL.
- Its clock: the cycle (0x1006; where that is 0 or missing the interpolation time period 0x60C2, else the default
  given) times the SYNCs it has seen. On a lock-step bus (``clocked``) its heartbeat and heartbeat consumer go on
  that clock (a test may give another: ``now``); in real time the consumer goes on the wall clock, polled
  (:meth:`SimulatedNode.poll`) by a watchdog thread.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import canopen
from canopen.objectdictionary import ODVariable
from canopen.sdo import SdoAbortedError

from rehabkit.canopen.bus.pdo_codec import PdoCodec
from rehabkit.canopen.simulated.device import Device
from rehabkit.canopen.simulated.errors import ErrorLog
from rehabkit.canopen.simulated.nmt_slave import NMT_BYTE, NmtSlave
from rehabkit.canopen.simulated.watchdogs import HeartbeatConsumer

SYNC_ID = 0x80
HEARTBEAT_LOST = 0x8130  # CiA 301/402 error code: life guard error or heartbeat error
COMMUNICATION = ((0x1006, 0), (0x60C2, 1), (0x60C2, 2))
ACTIVE = ("PRE-OPERATIONAL", "OPERATIONAL")
__all__ = ["NMT_BYTE", "SYNC_ID", "SimulatedNode"]
log = logging.getLogger(__name__)


class SimulatedNode:
    """Node ``node_id`` on ``network`` serving ``eds`` with ``extra`` objects; ``keys``: the (index, subindex) it
    acts on or produces, ``defaults`` their internal values where the EDS gives none; ``clocked``: its heartbeat on
    its own clock; ``now``: its watchdogs' clock [s]; ``cycle_us``: its cycle where its EDS and master set none.
    A subclass calls :meth:`boot` once it is ready."""

    watched: frozenset[tuple[int, int]] = frozenset()  # RPDO entries a subclass acts on (see pdo_written)

    def __init__(self, network: canopen.Network, node_id: int, eds: Path, keys: Iterable[tuple[int, int]],
                 defaults: Mapping[tuple[int, int], int] | None = None, clocked: bool = False,
                 now: Callable[[], float] | None = None, extra: Iterable[ODVariable] = (), cycle_us: int = 1000):
        self.node = Device(node_id, eds, extra)
        self.clocked, self._network, self.default_cycle_us = clocked, network, cycle_us
        self._defaults = dict(defaults or {})
        self._keys = tuple(dict.fromkeys((*COMMUNICATION, *keys)))
        self.values: dict[tuple[int, int], int] = {}
        self._clock_us, self.syncs = 0, 0
        self.now = now or ((lambda: self._clock_us * 1e-6) if clocked else time.monotonic)
        self.silent = False  # (an injected fault: cut off the bus)
        self.arrival: Callable[[float], float] | None = None  # a frame's timestamp → when it arrived, on ``now``'s
        # clock (real time: the watchdogs go on arrivals, not on when the reader got round to them; see arrivals.py)
        self.errors = ErrorLog(self.node, lambda: self.nmt.state in ACTIVE and not self.silent)
        self.consumer = HeartbeatConsumer(self.now, self.heartbeat_lost)
        self._consumers: dict[int, int] = {}  # 0x1016 sub-index → the node it watches
        self._maps_changed = True
        self._rx: dict[int, tuple[PdoCodec, bool, list]] = {}  # COB-ID → (map, synchronous, [newest frame or None])
        self._tx: list[tuple[PdoCodec, int, list]] = []  # (map, transmission type, [the data sent last])
        self._init_values(0, 0xFFFF)
        network.add_node(self.node)
        self.nmt = NmtSlave(self.node, network, lambda: self._clock_us, clocked, self._reset, self._nmt_changed)
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)

    def boot(self) -> None:
        """Its boot-up: into PRE-OPERATIONAL."""
        self.nmt.boot()

    # -- its values -----------------------------------------------------------------------------------------

    def _init_values(self, low: int, high: int) -> None:
        for key in self._keys:
            if low <= key[0] <= high:
                self.values.pop(key, None)  # (so the dictionary's own is read, not the one it had)
                value = self.node.value(*key)
                self.values[key] = self._defaults.get(key, 0) if value is None else value
        self.values[0x1001, 0] = self.errors.register

    @property
    def cycle_us(self) -> int:
        """Its cycle [µs]: 0x1006, else 0x60C2 (value × 10^index s), else its default."""
        v = self.values
        if v[0x1006, 0]:
            return v[0x1006, 0]
        if v[0x60C2, 1]:
            return max(1, round(v[0x60C2, 1] * 10.0 ** (v[0x60C2, 2] + 6)))
        return self.default_cycle_us

    @property
    def clock(self) -> int:
        """Its own time [µs]: the cycles it has seen, each as long as its cycle was."""
        return self._clock_us

    @property
    def emcy_sent(self) -> list[int]:
        """Every error code it raised (its EMCYs), in order."""
        return self.errors.raised

    @property
    def heartless(self) -> bool:
        return self.nmt.heartless

    @heartless.setter
    def heartless(self, value: bool) -> None:
        if value:
            self.nmt.stop_beating()

    def _on_read(self, index: int, subindex: int, od) -> int | None:
        value = self.errors.read(index, subindex)
        return self.values.get((index, subindex)) if value is None else value

    def value_written(self, key: tuple[int, int]) -> None:
        """A master wrote one of its ``values`` by SDO (a subclass acts on it)."""

    def pdo_written(self, key: tuple[int, int], at_sync: bool) -> None:
        """An RPDO brought one of :attr:`watched` (``at_sync``: taken at a SYNC; else at once)."""

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        key = (index, subindex)
        if key in self.values:
            self.values[key] = od.decode_raw(data)
            self.value_written(key)
        if 0x1400 <= index <= 0x1BFF:  # the master (re)configures a PDO: its maps read again, once it is written
            self._maps_changed = True
        elif index == 0x1016 and subindex > 0:  # watch a node's heartbeat: (node id << 16) | consumer time [ms]
            value = od.decode_raw(data)
            old = self._consumers.pop(subindex, None)
            if old is not None:
                self.consumer.configure(old, 0)
            node, ms = value >> 16 & 0x7F, value & 0xFFFF
            if node and ms:
                self._consumers[subindex] = node
                self.consumer.configure(node, ms)
                self._network.subscribe(0x700 + node, self._on_heartbeat)

    # -- NMT --------------------------------------------------------------------------------------------------

    def _reset(self, application: bool) -> None:
        """Reset node: its application's objects (0x2000-0x9FFF) restored, then (and alone: reset communication)
        its communication objects (0x1000-0x1FFF)."""
        if application:
            self.node.restore(0x2000, 0x9FFF)
            self._init_values(0x2000, 0x9FFF)
            self.errors.active.clear()
            self.application_reset()
        self.node.restore(0x1000, 0x1FFF)
        self._init_values(0x1000, 0x1FFF)
        self.consumer.clear()
        self._consumers.clear()
        self.errors.clear_history()
        self._maps_changed = True

    def application_reset(self) -> None:
        """Reset node: its application starts again (a subclass)."""

    def _nmt_changed(self, old: str, new: str) -> None:
        # the PDO maps the master wrote take effect as the node enters OPERATIONAL, before its first RPDO arrives
        if new == "OPERATIONAL" and self._maps_changed:
            self._take_maps()

    # -- PDOs -------------------------------------------------------------------------------------------------

    def _take_maps(self) -> None:
        for cob in self._rx:
            self._network.unsubscribe(cob, self._on_rpdo)
        self._rx, self._tx = {}, []
        for pdos, receiving in ((self.node.rpdo, True), (self.node.tpdo, False)):
            for pdo in pdos.map.values():
                try:
                    pdo.read(from_od=False)
                    codec = PdoCodec.of(pdo) if pdo.enabled and pdo.map else None
                except (KeyError, ValueError, SdoAbortedError) as exc:  # (a vendor's map of what it cannot serve)
                    log.info("node %d: %s not served (%s)", self.node.id, pdo.name, exc)
                    continue
                if codec is None:
                    continue
                for key in codec.keys:  # (mapped: process data from now on)
                    if key not in self.values:
                        self.values[key] = self.node.value(*key) or 0
                if receiving:
                    self._rx[codec.cob_id] = (codec, pdo.trans_type <= 240, [None])
                    self._network.subscribe(codec.cob_id, self._on_rpdo)
                else:
                    self._tx.append((codec, pdo.trans_type, [None]))
        self._maps_changed = False

    def _on_rpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        if self.nmt.state != "OPERATIONAL" or self.silent:
            return
        codec, synchronous, frame = self._rx[can_id]
        if synchronous:
            frame[0] = bytes(data)
        else:
            self._take(codec, bytes(data), at_sync=False)

    def _take(self, codec: PdoCodec, data: bytes, at_sync: bool) -> None:
        codec.unpack_into(data, self.values)
        for key in codec.keys:
            if key in self.watched:
                self.pdo_written(key, at_sync)

    def send_tpdos(self, at_sync: bool = True) -> None:
        """The TPDOs from the values as they stand: at a SYNC the synchronous ones due; the event-driven ones whose
        data changed."""
        if self.nmt.state != "OPERATIONAL" or self.silent:
            return
        self.values[0x1001, 0] = self.errors.register
        for codec, kind, sent in self._tx:
            if kind <= 240 and not at_sync:
                continue
            data = codec.pack(self.values)
            if (kind == 0 or kind > 240) and data == sent[0]:
                continue
            if 0 < kind <= 240 and self.syncs % kind:
                continue
            sent[0] = data
            self._network.send_message(codec.cob_id, data)

    # -- cycles -----------------------------------------------------------------------------------------------

    def tick(self) -> None:
        """Its clock one cycle on; on a lock-step bus its heartbeat when due and its watchdogs polled."""
        self._clock_us += self.cycle_us
        if self.clocked:
            self.nmt.tick()
            self.poll()

    def poll(self) -> None:
        """Its watchdogs, on its clock (``now``): the heartbeat consumer in PRE-OPERATIONAL and OPERATIONAL."""
        if self.nmt.state in ACTIVE:
            self.consumer.poll()

    def begin_cycle(self) -> bool:
        """A SYNC's first half: False where the node takes no part (STOPPED: CiA 301; or silenced); else its clock
        on and, OPERATIONAL, the RPDOs that came before it taken in."""
        if self.silent:
            return False
        self.tick()
        state = self.nmt.state
        if state == "OPERATIONAL":
            if self._maps_changed:  # (a map changed while OPERATIONAL: taken at the next cycle)
                self._take_maps()
            self.syncs += 1
            for codec, _, frame in self._rx.values():
                if frame[0] is not None:
                    self._take(codec, frame[0], at_sync=True)
                    frame[0] = None
        return state in ACTIVE

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        at = self.arrival(timestamp) if self.arrival is not None else None
        if not self.silent and self.consumer.heartbeat(can_id - 0x700, at):
            self.errors.recover(HEARTBEAT_LOST)

    def heartbeat_lost(self, node: int) -> None:
        """A node it watches fell silent (a subclass reacts)."""

    def send_emcy(self, code: int) -> None:
        """An error: its register, its history, its EMCY (where the NMT state lets it go out)."""
        self.errors.raise_error(code)
        self.values[0x1001, 0] = self.errors.register
