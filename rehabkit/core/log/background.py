"""One piece of a run's end done in a background thread while the caller goes on (a file's encoding, a disk wait)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any


def begin(work: Callable[..., Any], *args: Any, name: str = "rehabkit-finish") -> Callable[[], Any]:
    """Start ``work(*args)`` in a thread; returns the call that waits for it and gives its result, or raises its
    error in the caller's thread."""
    done: list[Any] = []
    failed: list[BaseException] = []

    def run() -> None:
        try:
            done.append(work(*args))
        except BaseException as exc:  # noqa: BLE001 (raised by the waiting call)
            failed.append(exc)

    thread = threading.Thread(target=run, name=name, daemon=True)
    thread.start()

    def wait() -> Any:
        thread.join()
        if failed:
            raise failed[0]
        return done[0]
    return wait
