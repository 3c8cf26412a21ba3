"""A lock-step CAN channel inside this process: the host's network, the simulated drives' and the trace's tap, each
frame sent queued for the others and delivered when the bus pumps, in the order sent.

canopen's documented way in for a custom backend (``Network.send_message`` sends through ``network.bus.send``,
``Network.notify`` takes each frame in) carries it; python-can's virtual bus did the same with a deep copy of each
frame for each receiver and a locked queue — per frame more than a simulated drive's whole cycle. One thread uses a
lock-step channel (the pump's), so it needs neither: receivers share the frame canopen made for the send, read only;
the trace's tap gets a copy of its own to stamp.
"""

from __future__ import annotations

import time
from collections import deque

import can
import canopen


class LockstepEnd:
    """One network's end of a :class:`LockstepChannel` (what ``canopen.Network.bus`` needs: ``send``)."""

    def __init__(self, channel: LockstepChannel):
        self.channel, self.inbox = channel, deque()
        self.channel_info = f"lock-step channel {channel.name}"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        msg.timestamp, msg.channel = time.time(), self.channel.name  # (as python-can's virtual bus stamps a frame)
        for end in self.channel.ends:
            if end is not self:
                end.inbox.append(msg)

    def deliver(self, network: canopen.Network) -> None:
        """Every frame queued for ``network``, into it."""
        inbox, notify = self.inbox, network.notify
        while inbox:
            msg = inbox.popleft()
            notify(msg.arbitration_id, msg.data, msg.timestamp)

    def frames(self):
        """The frames queued here, each a copy of its own (a tap stamps them), oldest first."""
        inbox = self.inbox
        while inbox:
            m = inbox.popleft()
            yield can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id, is_extended_id=m.is_extended_id,
                              is_remote_frame=m.is_remote_frame, dlc=m.dlc, data=m.data, channel=m.channel)

    def shutdown(self) -> None:
        if self in self.channel.ends:
            self.channel.ends.remove(self)
        self.inbox.clear()


class LockstepChannel:
    """The ends on one lock-step channel (``name``: as the trace names it)."""

    def __init__(self, name: str):
        self.name, self.ends = name, []

    def end(self) -> LockstepEnd:
        end = LockstepEnd(self)
        self.ends.append(end)
        return end
