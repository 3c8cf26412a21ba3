"""The CANopen cycles' deadlines on a general-purpose OS: how far apart a running host's SYNCs can come (what the
drives' SYNC watchdog allows by default, :data:`SYNC_TIMEOUT_MS`), and what a process running cycles does to keep
them — the host's loop (its cycle clock) and ``rehabkit drives`` (their bus reader and watchdog) alike, each measure
where this host permits it (a process may take one and not another: each is its own):

- ``fifo``: the threads that make the cycles in the real-time scheduling class (``SCHED_FIFO``): a thread of the
  ordinary class that became runnable waits its turn behind every other runnable one on its core. The host's loop
  thread at :data:`HOST_PRIORITY`, its hold and bus readers one above (on one CPU a real-time thread is not preempted
  by one of its own priority); the drives' reader at :data:`DRIVES_PRIORITY`, their watchdog one above. Permitted to
  root, to ``CAP_SYS_NICE`` or within ``ulimit -r``; elsewhere said once, and the cycles run in the ordinary class.
- ``affinity``: the host and the drives each on CPUs of their own (the drives on the last, the host on the others),
  so neither waits behind the other's threads.
- ``gc``: the collector off while the cycles run (``gc.disable``; the set-up's objects frozen first), on again at the
  end (the host: the run's end; the drives: whenever no drive is powered, between runs). Not kept: the run's loop
  already freezes what it built, and no difference showed.

``REHABKIT_DEADLINES`` picks them (comma-separated, or ``none``); its default, :data:`KEPT`, is what helped in
``benchmarks/canopen_two_process.py`` (the README's two-process run on a 2-core VM, 5 runs quiet and 5 with one core
busy each, late steps / missed TPDOs / SYNC→last TPDO p99 over those runs):

==================  =================================  =================================
measures            quiet                              one core busy
==================  =================================  =================================
none                1599 / 1552 / 1.95 ms              1183 / 2497 / 1.60 ms
gc,fifo             273 / 16 / 1.01 ms                 67 / 6 / 1.09 ms
gc,affinity         68 / 1129 / 1.54 ms                68 / 738 / 0.61 ms, 1 of 5 failed
fifo,affinity       12 / 6 / 0.61 ms                   15 / 18 / 0.55 ms
gc,fifo,affinity    111 / 278 / 0.55 ms (20 runs)      67 / 42 / 0.50 ms (20 runs)
==================  =================================  =================================

Without ``fifo`` the drives' reader starved for up to 48 ms with one core busy (a false SYNC loss before their
watchdog waited for it: see :mod:`~rehabkit.canopen.simulated.arrivals`); without ``affinity`` the host's steps came
late ten times as often.
"""

from __future__ import annotations

import contextlib
import gc
import os
import sys
import threading
from collections.abc import Iterable

HOLD_AFTER_CYCLES = 2  # a step this late is not coming in time: the drives get their SYNC from the hold
# The drives' SYNC watchdog, by default (the canopen backend's sync_timeout_ms, `rehabkit drives --sync-timeout-ms`):
# the longest a running host's SYNCs can be apart, so that it trips when the host is gone and not when it is merely a
# general-purpose OS. A step HOLD_AFTER_CYCLES cycles late gets its SYNC from the hold, so the SYNCs come at most
# (HOLD_AFTER_CYCLES + 1) cycles apart while the host's threads run; on top comes the longest the OS stalls the whole
# process (none of its threads runs):  timeout = (HOLD_AFTER_CYCLES + 1) × CYCLE_MS + STALL_MS.
# CYCLE_MS: 4 ms (250 Hz), the longest cycle the README's rates use (500 Hz: 2 ms). STALL_MS: the most this 2-core VM
# was seen to stall a process (benchmarks/canopen_two_process.py, 2 × 20 runs and more): a thread sleeping 1 ms at a
# time overslept by up to 18.7 ms with one core busy (10.6 ms in 30 s, 6.4 ms quiet); the drives received SYNCs up
# to 20.0 ms apart (3 cycles of 2 ms + 14 ms) with one core busy and the host in the ordinary class, 31.2 ms once
# while the host was still in it at the start with the other tests running; the README's 10-20 ms under the tests.
# 32 ms: a host really gone stops its drives within it, and the host's heartbeat (60 ms) watches too.
CYCLE_MS, STALL_MS = 4.0, 20.0
SYNC_TIMEOUT_MS = (HOLD_AFTER_CYCLES + 1) * CYCLE_MS + STALL_MS
KEPT = "fifo,affinity"  # (see the module's doc: the measures that helped, as measured)
HOST_PRIORITY, DRIVES_PRIORITY = 40, 45  # SCHED_FIFO 1-99: below the kernel's own threads (50: its IRQ threads)
_said: set[str] = set()


def measures() -> frozenset[str]:
    """The measures this process takes (``REHABKIT_DEADLINES``, default :data:`KEPT`)."""
    given = os.environ.get("REHABKIT_DEADLINES", KEPT)
    return frozenset(m.strip() for m in given.split(",") if m.strip() and m.strip() != "none")


def _say_once(key: str, text: str) -> None:
    if key not in _said:
        _said.add(key)
        print(f"rehabkit: {text}", file=sys.stderr, flush=True)


def hold_collector() -> bool:
    """``gc``: what exists now frozen, the collector off (until :func:`release_collector`). Returns whether it did."""
    if "gc" not in measures() or not gc.isenabled():
        return False
    gc.collect(0)
    gc.freeze()
    gc.disable()
    return True


def release_collector() -> None:
    """The collector on again."""
    gc.enable()


def realtime(threads: Iterable[threading.Thread], priority: int) -> bool:
    """``fifo``: ``threads`` (started) in SCHED_FIFO at ``priority``. Returns whether they are; not permitted here:
    said once on stderr, and they stay in the ordinary class."""
    if "fifo" not in measures() or not hasattr(os, "sched_setscheduler"):
        return False
    try:
        for t in threads:
            if t.native_id is not None:
                os.sched_setscheduler(t.native_id, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        _say_once("fifo", "the real-time scheduling class (SCHED_FIFO) is not permitted to this process (root, "
                  "CAP_SYS_NICE or `ulimit -r` permits it): the CANopen cycles run in the ordinary class")
        return False
    except OSError as exc:  # (a thread that ended meanwhile)
        _say_once("fifo", f"SCHED_FIFO not taken ({exc}): the CANopen cycles run in the ordinary class")
        return False
    return True


def ordinary(threads: Iterable[threading.Thread]) -> None:
    """``threads`` back in the ordinary class (those still alive)."""
    if not hasattr(os, "sched_setscheduler"):
        return
    for t in threads:
        try:
            if t.native_id is not None and t.is_alive():
                os.sched_setscheduler(t.native_id, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


def pin(role: str) -> set[int] | None:
    """``affinity``: this process on CPUs of its own — ``drives`` the last allowed, ``host`` the others — where it
    may run on two or more. Returns the CPUs it had (for :func:`unpin`), or None where it did nothing."""
    if "affinity" not in measures() or not hasattr(os, "sched_setaffinity"):
        return None
    had = os.sched_getaffinity(0)
    cpus = sorted(had)
    if len(cpus) < 2:
        return None
    _all_threads({cpus[-1]} if role == "drives" else set(cpus[:-1]))
    return had


def unpin(had: set[int] | None) -> None:
    """This process on the CPUs :func:`pin` found it on."""
    if had is not None:
        _all_threads(had)


def _all_threads(cpus: set[int]) -> None:
    for tid in os.listdir("/proc/self/task"):  # (Linux sets a thread's: each of the process's, native ones too)
        with contextlib.suppress(OSError):  # (one that ended meanwhile)
            os.sched_setaffinity(int(tid), cpus)


def cycle_threads(*more: threading.Thread) -> list[threading.Thread]:
    """The calling thread, the bus readers (python-can's notifier threads) and ``more``: the threads a cycle waits
    on (not a camera's renderer, which runs as the idle class)."""
    readers = [t for t in threading.enumerate() if t.name.startswith("Notifier for bus")]
    return [threading.current_thread(), *readers, *more]
