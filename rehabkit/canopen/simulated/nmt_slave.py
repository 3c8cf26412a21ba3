"""A simulated device's NMT slave (CiA 301, "network management"): its boot-up, the NMT commands it obeys and its
heartbeat.

Created or reset, a device sends its boot-up (0x700 + node id, one byte 0x00) and enters PRE-OPERATIONAL by itself.
Start (0x01) takes it to OPERATIONAL, stop (0x02) to STOPPED, enter pre-operational (0x80) back; reset node (0x81)
restores its application's objects and then its communication objects, reset communication (0x82) only those — the
device's :attr:`NmtSlave.on_reset` — and both boot it again. Its heartbeat (0x1017 ms, 0 none) says its state in one
byte: 0x7F pre-operational, 0x05 operational, 0x04 stopped. canopen's own slave sends it on the wall clock (a
periodic frame python-can sends); on a lock-step bus it goes on the device's own clock (:meth:`NmtSlave.tick`), so
every run decides the same way. canopen's slave keeps the state (``node.nmt.state``); its handling of commands is
replaced, since it neither boots again after a reset nor leaves INITIALISING.
"""

from __future__ import annotations

from collections.abc import Callable

import canopen

from rehabkit.canopen.simulated.device import Device

NMT_BYTE = {"INITIALISING": 0x00, "STOPPED": 0x04, "OPERATIONAL": 0x05, "PRE-OPERATIONAL": 0x7F}
START, STOP, ENTER_PRE_OPERATIONAL, RESET_NODE, RESET_COMMUNICATION = 0x01, 0x02, 0x80, 0x81, 0x82
_ENTERS = {START: 0x05, STOP: 0x04, ENTER_PRE_OPERATIONAL: 0x7F}


class NmtSlave:
    """``device``'s NMT slave on ``network``; ``clock``: the device's own time [µs] its heartbeat goes on where
    ``clocked``. ``on_reset(application)``: restore the objects a reset restores (see the module's doc);
    ``on_state(old, new)``: the state changed."""

    def __init__(self, device: Device, network: canopen.Network, clock: Callable[[], int], clocked: bool,
                 on_reset: Callable[[bool], None], on_state: Callable[[str, str], None]):
        self.device, self.network, self.clock, self.clocked = device, network, clock, clocked
        self.on_reset, self.on_state = on_reset, on_state
        self.heartless = False  # (an injected fault: its heartbeat stops)
        self._beat_us, self._next_beat = 0, 0
        if clocked:  # (canopen's slave would start a wall-clock timer: here the device's own clock sends it)
            device.nmt.start_heartbeat = self._start_clocked
            device.nmt.stop_heartbeat = lambda: self._start_clocked(0)
        network.subscribe(0x000, self._on_command)

    @property
    def state(self) -> str:
        """'PRE-OPERATIONAL', 'OPERATIONAL', 'STOPPED' (or 'INITIALISING' while it boots)."""
        return self.device.nmt.state

    def boot(self) -> None:
        """Its boot-up frame, then PRE-OPERATIONAL with its heartbeat (0x1017) started."""
        nmt = self.device.nmt
        nmt.stop_heartbeat()
        self._enter(0x00)
        self.network.send_message(0x700 + self.device.id, b"\x00")
        self._enter(0x7F)
        nmt.start_heartbeat(self.device.value(0x1017) or 0)

    def _on_command(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) != 2 or data[1] not in (0, self.device.id):
            return
        command = data[0]
        if command in _ENTERS:
            self._enter(_ENTERS[command])
        elif command in (RESET_NODE, RESET_COMMUNICATION):
            self.device.nmt.stop_heartbeat()
            self.on_reset(command == RESET_NODE)
            self.boot()

    def _enter(self, code: int) -> None:
        nmt = self.device.nmt
        old = nmt.state
        nmt._state = code  # (canopen's slave keeps the state: node.nmt.state reads it)
        if not self.clocked:
            nmt.update_heartbeat()
        if nmt.state != old:
            self.on_state(old, nmt.state)

    def stop_beating(self) -> None:
        """Its heartbeat stops (an injected fault)."""
        self.heartless = True
        if not self.clocked:
            self.device.nmt.stop_heartbeat()

    def _start_clocked(self, ms: int) -> None:
        self._beat_us, self._next_beat = ms * 1000, self.clock()

    def tick(self) -> None:
        """On a lock-step bus: its heartbeat when due on its own clock."""
        if self._beat_us and self.clock() >= self._next_beat and not self.heartless:
            self._next_beat += self._beat_us
            self.network.send_message(0x700 + self.device.id, bytes([NMT_BYTE.get(self.state, 0x05)]))
