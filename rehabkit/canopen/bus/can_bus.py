"""The host's CAN bus: its CANopen network, the simulated drives' network beside it when the run starts them, and
the trace of every frame.

In real time each network reads its bus in canopen's usual way (a python-can ``Notifier`` thread). On a lock-step
bus (a channel in this process: :mod:`~rehabkit.canopen.bus.lockstep_channel`) nothing runs by itself: every frame
the host sends is delivered at once — to the drives' network, then the trace, then the host's own network — in this
thread, in the order sent; so an SDO's answer is there when canopen's client looks for it and a cycle's TPDOs are in
when its SYNC has been sent. Deterministic, and as fast as both sides compute.

The trace is a third python-can bus on the same channel, each frame written by python-can's own writer for the file's
kind (``.asc``, ``.blf``, candump ``.log``): into a temporary name, renamed when the bus closes (never half a file).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import time
from collections.abc import Callable
from pathlib import Path

import can
import canopen

from rehabkit.canopen.bus.lockstep_channel import LockstepChannel, LockstepEnd

_CHANNELS = itertools.count()


class _PumpedNetwork(canopen.Network):
    """A network whose every frame sent is delivered before ``send_message`` returns (``pump``)."""

    pump: Callable[[], None] | None = None

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        super().send_message(can_id, data, remote)
        if self.pump is not None:
            self.pump()


def sent_by_host(can_id: int, master_id: int) -> bool:
    """A frame the master sends (the trace's Tx): NMT, SYNC, RPDOs, SDO requests, its own heartbeat."""
    return can_id in (0x000, 0x080, 0x700 + master_id) or 0x200 <= can_id < 0x580 and can_id & 0x7F and \
        (can_id >> 7) % 2 == 0 or 0x600 < can_id < 0x680


class CanBus:
    """The host's ``network`` on ``interface``/``channel`` (None: a virtual channel of its own), with a ``drives``
    network on it when simulated drives run in this process; ``trace``: the file every frame goes into;
    ``lockstep``: frames delivered as sent, timestamps from ``clock``."""

    def __init__(self, interface: str | None = None, channel: str | None = None, bitrate: int = 1_000_000,
                 simulated: bool = False, lockstep: bool = False, trace: Path | None = None,
                 clock: Callable[[], float] | None = None, master_id: int = 127):
        if interface is None:
            interface, channel = "virtual", f"rehabkit-{os.getpid()}-{next(_CHANNELS)}"
        kw = {"interface": interface, "channel": channel, "receive_own_messages": False}
        if interface not in ("virtual", "udp_multicast"):
            kw["bitrate"] = bitrate
        self.lockstep, self.clock, self.master_id, self._opened = lockstep, clock, master_id, time.time()
        self.network: canopen.Network = _PumpedNetwork() if lockstep else canopen.Network()
        self.drives: canopen.Network | None = None
        self._buses: list[can.BusABC | LockstepEnd] = []
        self._notifiers: list[can.Notifier] = []
        self.frames = 0
        self.trace, self._part, self._writer, self._tap = trace, None, None, None
        self._trace_channel: int | str | None = channel  # (a traced frame's channel, as its writer reads it)
        if lockstep and interface != "virtual":
            raise ValueError(f"a lock-step bus is a channel of this process, not {interface} {channel}")
        self._channel = LockstepChannel(channel) if lockstep else None
        try:
            if simulated:
                self.drives = canopen.Network(self._open(kw))
            if trace is not None:
                trace.parent.mkdir(parents=True, exist_ok=True)
                self._part = trace.with_name(f".{trace.stem}.part{trace.suffix}")  # (the suffix picks the writer)
                self._writer = can.Logger(self._part)
                self._tap = self._open(kw)
                # python-can's ASC and BLF writers number a frame's channel from its name (channel2int: a regular
                # expression a frame, 1.2 µs: 0.1 s of HIT's 2.2 s on six drives traced); the frames here carry that
                # number, worked out once: the same file. (candump's writer writes the name itself: it keeps it.)
                if isinstance(self._writer, (can.ASCWriter, can.BLFWriter)):
                    self._trace_channel = can.util.channel2int(channel)
            self.network.bus = self._open(kw)
            if lockstep:
                self.network.pump = self.pump
            else:
                for net in (self.drives, self.network):
                    if net is not None:
                        self._notifiers.append(can.Notifier(net.bus, net.listeners, 0.1))
                if self._tap is not None:
                    self._notifiers.append(can.Notifier(self._tap, [self._count, self._writer], 0.1))
        except BaseException:
            self.close(keep_trace=False)
            raise

    def _open(self, kw: dict) -> can.BusABC | LockstepEnd:
        bus = self._channel.end() if self._channel is not None else can.Bus(**kw)
        self._buses.append(bus)
        return bus

    def _count(self, msg: can.Message) -> None:
        msg.is_rx = not sent_by_host(msg.arbitration_id, self.master_id)
        self.frames += 1

    def pump(self) -> None:
        """Deliver every frame sent so far (lock-step): the drives', the trace's, the host's."""
        if self.drives is not None:
            self.drives.bus.deliver(self.drives)
        if self._tap is not None:
            for msg in self._tap.frames():
                if self.clock is not None:  # (the bus's own clock, from the moment it opened)
                    msg.timestamp = self._opened + self.clock()
                msg.is_rx = not sent_by_host(msg.arbitration_id, self.master_id)
                msg.channel = self._trace_channel
                self._writer.on_message_received(msg)
                self.frames += 1
        self.network.bus.deliver(self.network)

    def close(self, keep_trace: bool = True) -> None:
        """Stop reading, close the buses; the trace renamed into place (or removed)."""
        for notifier in self._notifiers:
            notifier.stop(0.5)
        self._notifiers = []
        if self.lockstep and self._buses:
            with contextlib.suppress(Exception):  # (closing after a failure: the trace keeps what it has)
                self.pump()  # (the last frames sent, into the trace)
        for bus in self._buses:
            bus.shutdown()
        self._buses = []
        self.network.bus = None
        if self._writer is not None:
            self._writer.stop()
            self._writer = None
            if keep_trace:
                os.replace(self._part, self.trace)
            else:
                self._part.unlink(missing_ok=True)
