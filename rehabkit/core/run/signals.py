"""How a run takes the signals that end it: SIGTERM as Ctrl-C is, and both held off while the robot is brought to
rest, its hardware released and the files closed (in the main thread, where Python takes signals; elsewhere each is
a no-op)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["Terminated", "signals_deferred", "signals_held", "terminated_as_interrupt"]


class Terminated(KeyboardInterrupt):
    """SIGTERM (a service manager stopping the program), taken as Ctrl-C is: the robot brought to rest, the files
    closed."""

    signal = "SIGTERM"


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def terminated_as_interrupt() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` while a run goes."""
    if not _main_thread():
        yield
        return

    def terminated(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def signals_held(*signums: int) -> Iterator[None]:
    """``signums`` (default SIGINT and SIGTERM) ignored meanwhile: a second Ctrl-C, or a service manager's SIGTERM,
    must not cut short a robot's stop, leave drives powered or a bridge running, or a file half-written."""
    if not _main_thread():
        yield
        return
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in signums or (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM taken when the block is over instead of inside it: an extension's tap writing its file
    (a bag's chunk) is not cut mid-record — Ctrl-C raised inside the mcap writer left a torn record in the chunk, and
    every message after it in that chunk unreadable. The first signal that came is raised again at the end, to the
    handler that was in place."""
    if not _main_thread():
        yield
        return
    came: list[int] = []

    def later(signum, frame):
        came.append(signum)

    previous = {s: signal.signal(s, later) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if came:
            signal.raise_signal(came[0])
