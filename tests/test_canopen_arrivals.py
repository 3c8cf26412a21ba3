"""The simulated drives' watchdogs judge by when frames arrived, once their reader has had every one that came
(rehabkit.canopen.simulated.arrivals): a stall of the drives' own process is not blamed on the host. Deterministic: a
socket pair stands in for the bus's socket, the test plays the notifier thread, and the clocks are the test's."""

import socket
import time

import can
import pytest

from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS
from rehabkit.canopen.simulated.arrivals import Arrivals
from rehabkit.canopen.simulated.watchdogs import SyncWatchdog


class _Bus:
    """A bus on one end of a socket pair: a frame is a byte."""

    def __init__(self, sock: socket.socket):
        self.sock = sock

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        self.sock.settimeout(timeout)
        try:
            return can.Message(arbitration_id=self.sock.recv(1)[0], timestamp=time.time())
        except TimeoutError:
            return None


class _Network:
    def __init__(self, bus: _Bus):
        self.bus, self.listeners = bus, []
        self.notifier = self

    def add_listener(self, listener) -> None:
        self.listeners.append(listener)


def test_a_frame_counts_as_unread_from_the_socket_until_the_drives_have_had_it():
    wire, end = socket.socketpair()
    with wire, end:
        network = _Network(_Bus(end))
        arrivals = Arrivals(network)
        assert arrivals.caught_up()
        wire.send(b"\x80")  # a SYNC arrives; the reader has not yet run (this process stalled)
        assert not arrivals.caught_up()
        msg = network.bus.recv(0)  # the notifier thread reads it (the wrapped recv)...
        assert msg is not None and msg.arbitration_id == 0x80
        assert not arrivals.caught_up()  # ...out of the socket, not yet through the drives
        for listener in network.listeners:
            listener(msg)
        assert arrivals.caught_up()
        assert network.bus.recv(0) is None and arrivals.caught_up()


def test_the_sync_watchdog_goes_on_arrivals_not_on_when_a_late_reader_handled_them():
    timeout = SYNC_TIMEOUT_MS * 1e-3
    now = [100.0]
    watchdog = SyncWatchdog(lambda: now[0])
    watchdog.feed(True, at=100.0)
    now[0] = 100.0 + timeout + 0.005  # its process stalled: the next SYNC, which came in time, handled only now
    watchdog.feed(True, at=100.0 + timeout - 0.001)
    assert not watchdog.expired(True) and watchdog.fired == []
    now[0] = 100.0 + 2 * timeout  # then no SYNC at all: a host gone
    assert watchdog.expired(True) and abs(watchdog.fired[0] - (timeout + 0.001)) < 1e-9


@pytest.mark.realtime  # (the kernel's wall clock against the monotonic one, read moments apart)
def test_a_frames_timestamp_is_when_it_arrived_unless_it_cannot_be():
    assert abs(Arrivals.at(time.time() - 0.005) - (time.monotonic() - 0.005)) < 0.002  # (5 ms ago)
    t = time.monotonic()
    assert Arrivals.at(0.0) >= t and Arrivals.at(time.time() + 60) >= t  # (none; from the future)
