"""When frames reached the simulated drives, and whether the drives have read them all: what their watchdogs judge by.

A real drive's firmware notes a SYNC as it comes off the wire, and does not stall. The simulated drives are a
process on a general-purpose OS, which the scheduler or the collector stalls now and then while the frames wait in
the socket, unread; a watchdog thread waking from such a stall of its own process would find "no SYNC for N ms" and
blame the host for it. So, as a drive would:

- a frame's time is when it *arrived*: the kernel's receive timestamp python-can gives it (``msg.timestamp``:
  SO_TIMESTAMPNS on udp_multicast and socketcan; the sender's time on a virtual bus), not when the reader got round
  to it (:meth:`Arrivals.at`);
- a watchdog judges only once the reader has caught up — no frame waiting in the socket, none read but not yet
  handed to the drives (:meth:`Arrivals.caught_up`) — so every frame that arrived before it looks has been counted.
  Frames waiting are the bus alive; only a reader that has not caught up once in a second (its process can no
  longer keep up with its bus: :data:`~rehabkit.canopen.simulated.rig.READER_BEHIND_S`) is judged on what it has.

The reader is python-can's notifier thread; its bus's ``recv`` is wrapped so that a frame counts as "being handed
over" from before the socket is read until the last listener had it (between the two, neither the socket nor the
drives show it). On a bus without a file descriptor (python-can's ``virtual``, the run's own drives in its own
process) the queue is looked at instead.
"""

from __future__ import annotations

import select
import time

import can
import canopen

MAX_AGE_S = 1.0  # (a timestamp from another clock, or none: the frame taken as arriving when read)


class Arrivals:
    """What has reached ``network``'s reader (see the module's doc)."""

    def __init__(self, network: canopen.Network):
        bus = network.bus
        self.handing = False  # a frame read from the socket, not yet through every listener
        self._queue = getattr(bus, "queue", None)  # (python-can's virtual bus)
        try:
            self._fd = bus.fileno()
        except (NotImplementedError, AttributeError, OSError):  # (a bus with no socket: python-can's virtual one)
            self._fd = -1
        notifier = getattr(network, "notifier", None)
        if self._fd >= 0 and notifier is not None:
            read = bus.recv

            def recv(timeout: float | None = None) -> can.Message | None:
                if not select.select([self._fd], [], [], timeout)[0]:
                    return None
                self.handing = True  # (before the socket is read: the frame is never in neither place)
                msg = read(0)
                self.handing = msg is not None
                return msg

            bus.recv = recv  # (the notifier looks it up each time round)
            notifier.add_listener(self._handed)  # (after canopen's own: the drives have had it)

    def _handed(self, msg: can.Message) -> None:
        self.handing = False

    @staticmethod
    def at(timestamp: float) -> float:
        """When a frame stamped ``timestamp`` (epoch seconds, python-can's) arrived, on ``time.monotonic``."""
        now = time.monotonic()
        age = time.time() - timestamp
        return now - age if 0.0 <= age <= MAX_AGE_S else now

    def caught_up(self) -> bool:
        """Whether every frame that arrived before this call has been handed to the drives."""
        if self._queue is not None:
            waiting = not self._queue.empty()
        elif self._fd >= 0:
            try:
                waiting = bool(select.select([self._fd], [], [], 0)[0])
            except (OSError, ValueError):  # (the bus closing)
                waiting = False
        else:
            waiting = False
        return not waiting and not self.handing
