"""Make the control process as real-time as this OS allows, and say what it got.

Pinned to one core, SCHED_FIFO with SCHED_RESET_ON_FORK (children of the loop
do not inherit real-time priority), garbage collection frozen and disabled.
Where the OS refuses (no root, no CAP_SYS_NICE), the loop still runs and the
operator sees a notice saying so.
"""

from __future__ import annotations

import gc
import os
from dataclasses import dataclass


@dataclass(frozen=True)
class RealtimeReport:
    fifo: bool
    cpu: int | None
    priority: int
    notice: str


def enter_realtime(cpu: int | None = None, priority: int = 80, fifo: bool = True) -> RealtimeReport:
    """Pin, raise priority, freeze gc; never raises for lack of privilege."""
    notices = []
    pinned = None
    cpus = sorted(os.sched_getaffinity(0))
    target = cpus[-1] if cpu is None else cpu
    try:
        os.sched_setaffinity(0, {target})
        pinned = target
    except OSError as exc:
        notices.append(f"not pinned to CPU {target}: {exc.strerror}")
    got_fifo = False
    if fifo:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                                  os.sched_param(priority))
            got_fifo = True
        except OSError as exc:
            notices.append(f"SCHED_FIFO refused ({exc.strerror}): running at normal priority, "
                           "expect more lateness")
    gc.collect()
    gc.freeze()
    gc.disable()
    return RealtimeReport(fifo=got_fifo, cpu=pinned, priority=priority if got_fifo else 0,
                          notice="; ".join(notices))
