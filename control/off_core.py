"""A client's threads keep off the core its real-time controller claimed (``rt/realtime.py``).

On that core a client thread waits out the controller's spin and tick at SCHED_FIFO, so the
commands it sends go out just after a tick and wait a whole period for the next: beside a CPU
burner (which pushes the client onto the controller's core) an API command took a median
1.03 ms from the call to the valve, and 0.67 ms with the client on the other core
(``benchmarks/loop.py``). Every thread of the process is moved off the core (threads made later
inherit it) while the controller lives, unless no core would be left (two controllers on two
cores in one process); when the last controller on that core is let go, the threads may use
it again.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections import Counter
from collections.abc import Callable

_lock = threading.Lock()
_kept_off: Counter[int] = Counter()  # core -> live controllers of this process on it


def controller_core(pid: int) -> int | None:
    """The one core process ``pid`` (a controller) is pinned to, or None if not pinned to one."""
    try:
        cores = os.sched_getaffinity(pid)
    except OSError:  # gone already
        return None
    return next(iter(cores)) if len(cores) == 1 else None


def keep_off(core: int) -> bool:
    """Move every thread of this process off ``core``; False (nothing changed) when that would
    leave the calling thread no core. After True, ``come_back(core)`` once the controller is
    gone."""
    with _lock:
        if _kept_off[core]:
            _kept_off[core] += 1
            return True
        allowed = os.sched_getaffinity(0)
        if core not in allowed or not allowed - {core}:
            return False
        _kept_off[core] += 1
        _each_thread(lambda cores: cores - {core})
        return True


def come_back(core: int) -> None:
    """One controller on ``core`` is gone; with the last, the threads may use it again."""
    with _lock:
        _kept_off[core] -= 1
        if _kept_off[core] > 0:
            return
        del _kept_off[core]
        _each_thread(lambda cores: cores | {core})


def _each_thread(change: Callable[[set[int]], set[int]]) -> None:
    """Set every thread's affinity to ``change(its affinity)`` (Linux sets one thread's); a
    thread that ended meanwhile, or that would be left no core, is skipped."""
    for task in os.listdir("/proc/self/task"):
        tid = int(task)
        with contextlib.suppress(OSError):
            if cores := change(os.sched_getaffinity(tid)):
                os.sched_setaffinity(tid, cores)
