"""What every simulated CANopen device of rehabkit's does besides its own job: a ``canopen.LocalNode`` serving its
EDS (SDO server, NMT slave, EMCY producer: canopen's), with what the library leaves to a device.

- The PDO maps are the master's: written by SDO into the dictionary and read back from it as the node starts
  (NMT start) or at the first SYNC after they change; RPDO frames are kept as they come, TPDOs sent at the SYNC, each
  in one ``struct`` (:mod:`~rehabkit.canopen.bus.pdo_codec`).
- Its live values (``live``: the process data) are served to SDO reads as they stand; its parameters (``par``) are
  read once a master writes them.
- Heartbeats: a node it is told to watch (0x1016) silent longer than its consumer time is reported
  (:meth:`SimulatedNode.heartbeat_lost`), on the node's own clock: the SYNCs seen times the communication cycle
  period (0x1006). On a lock-step bus its own heartbeat (0x1017) goes on that clock too, so every run decides the
  same way; in real time canopen's NMT slave sends it.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import canopen

from rehabkit.canopen.bus.pdo_codec import PdoCodec

SYNC_ID = 0x80
NMT_BYTE = {"INITIALISING": 0x00, "STOPPED": 0x04, "OPERATIONAL": 0x05, "PRE-OPERATIONAL": 0x7F}


class SimulatedNode:
    """Node ``node_id`` on ``network`` serving ``eds``; ``parameters`` and ``live``: the (index, subindex) it acts on
    and the ones it produces or consumes each cycle; ``clocked``: heartbeats on the SYNC clock."""

    def __init__(self, network: canopen.Network, node_id: int, eds: Path, parameters: Iterable[tuple[int, int]],
                 live: Iterable[tuple[int, int]], clocked: bool = False):
        self.node = canopen.LocalNode(node_id, str(eds))
        network.add_node(self.node)
        self.clocked, self._network = clocked, network
        self.par = {(i, s): self.node.sdo[i].raw if not s else self.node.sdo[i][s].raw
                    for i, s in ((0x1006, 0), *parameters)}
        self.live = {k: 0 for k in live}
        self._maps_changed = True
        self._rx: dict[int, tuple[PdoCodec, list]] = {}  # COB-ID → (its map, [the newest frame's data or None])
        self._tx: list[PdoCodec] = []
        if clocked:  # (canopen's NMT slave would start a wall-clock timer: this node beats on its own clock)
            self.node.nmt.start_heartbeat = self._start_heartbeat
        self._beat_us, self._next_beat = 0, 0
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        network.subscribe(0x000, self._on_nmt)
        self.syncs = 0
        self._heard: dict[int, int] = {}  # a watched node → when its heartbeat came last [µs, this node's clock]
        self._watch: dict[int, int] = {}  # a watched node → its consumer time [µs]
        self.emcy_sent: list[int] = []
        self.silent = self.heartless = False  # (injected faults: cut off the bus; its heartbeat stops)
        self.unheard = 0  # cycles since it was cut off

    @property
    def clock(self) -> int:
        """The node's time [µs, exact]: SYNCs seen times the communication cycle period."""
        return self.syncs * self.par[0x1006, 0]

    def _start_heartbeat(self, ms: int) -> None:
        self._beat_us, self._next_beat = ms * 1000, self.clock

    def _on_read(self, index: int, subindex: int, od) -> int | None:
        return self.live.get((index, subindex))

    def parameter_written(self, index: int, subindex: int) -> None:
        """A master wrote one of ``par`` (a subclass acts on it)."""

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        if (index, subindex) in self.par:
            self.par[index, subindex] = od.decode_raw(data)
            self.parameter_written(index, subindex)
        elif (index, subindex) in self.live:
            self.live[index, subindex] = od.decode_raw(data)
        elif 0x1400 <= index <= 0x1BFF:  # the master (re)configures a PDO: its maps read again, once it is written
            self._maps_changed = True
        elif index == 0x1016 and subindex > 0:  # watch a node's heartbeat: (node id << 16) | consumer time [ms]
            value = od.decode_raw(data)
            node, ms = value >> 16 & 0x7F, value & 0xFFFF
            if node and ms:
                self._watch[node], self._heard[node] = ms * 1000, self.clock
                self._network.subscribe(0x700 + node, self._on_heartbeat)

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._heard[can_id - 0x700] = self.clock

    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        # the PDO maps the master wrote take effect as the node enters OPERATIONAL (NMT start: command 1, for this
        # node or all), before the first RPDO of the cycle arrives
        if len(data) == 2 and data[0] == 1 and data[1] in (0, self.node.id) and self._maps_changed:
            self._take_maps()

    def _on_rpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._rx[can_id][1][0] = bytes(data)

    def _take_maps(self) -> None:
        self.node.rpdo.read(from_od=False)
        self.node.tpdo.read(from_od=False)
        for cob in self._rx:
            self._network.unsubscribe(cob, self._on_rpdo)
        self._rx = {}
        for pdo in self.node.rpdo.map.values():
            if pdo.enabled and pdo.map:
                codec = PdoCodec.of(pdo)
                self._rx[codec.cob_id] = (codec, [None])
                self._network.subscribe(codec.cob_id, self._on_rpdo)
        self._tx = [PdoCodec.of(p) for p in self.node.tpdo.map.values() if p.enabled and p.map]
        self._maps_changed = False

    def begin_cycle(self) -> bool:
        """A SYNC's first half: False where the node takes no part (not OPERATIONAL: CiA 301; or silenced); else its
        clock on, watched heartbeats checked, its own sent when due, the RPDOs that came before it taken in."""
        if self.node.nmt.state != "OPERATIONAL" or self.silent:
            return False
        if self._maps_changed:  # (a map changed while OPERATIONAL: taken at the next cycle)
            self._take_maps()
        self.syncs += 1
        now = self.clock
        for node, limit in self._watch.items():
            if now - self._heard[node] > limit:
                self.heartbeat_lost(node)
        if self._beat_us and now >= self._next_beat and not self.heartless:
            self._next_beat += self._beat_us
            self._network.send_message(0x700 + self.node.id, bytes([NMT_BYTE.get(self.node.nmt.state, 0x05)]))
        for codec, frame in self._rx.values():
            if frame[0] is not None:
                codec.unpack_into(frame[0], self.live)
        return True

    def send_tpdos(self) -> None:
        """The TPDOs, from the live values as they stand."""
        for codec in self._tx:
            self._network.send_message(codec.cob_id, codec.pack(self.live))

    def heartbeat_lost(self, node: int) -> None:
        """A node it watches fell silent (a subclass reacts)."""

    def send_emcy(self, code: int, register: int = 0x01) -> None:
        self.emcy_sent.append(code)
        if not self.silent:  # (cut off the bus, it says it to nobody)
            self.node.emcy.send(code, register)
