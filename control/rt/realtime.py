"""Make the control process as real-time as this OS allows, and say what it got.

Pinned to one core, SCHED_FIFO with SCHED_RESET_ON_FORK (children of the loop
do not inherit real-time priority), garbage collection frozen and disabled.
Where the OS refuses (no root, no CAP_SYS_NICE), the loop still runs and the
operator sees a notice saying so.

The core is the highest-numbered one no other servodesk controller on this host has
claimed (a lock file per core, held for the process's life): two controllers (a rig
and a robot, or a service beside a TUI's own) at the same priority on one core wait
for each other's ticks, which late wake-ups and overruns show, while another core
serves neither. When every core is claimed, the last is shared, and the report says so
(``shared``): the control process then runs no warm-up (``control/rt/warmup.py``), whose
window before its own deadline would hold the other controller's ticks.
"""

from __future__ import annotations

import fcntl
import gc
import os
import stat
from dataclasses import dataclass
from pathlib import Path

# every controller on the host sees the same claims; a test spreading its own controllers
# claims apart from the others on the host (another test worker's, a benchmark's). Read at
# each claim: a controller is a fork of a server started with an older environment.
CLAIMS_ENV = "SERVODESK_CPU_CLAIMS"


@dataclass(frozen=True)
class RealtimeReport:
    fifo: bool
    cpu: int | None
    priority: int
    notice: str
    shared: bool = False  # every core was claimed: this one runs beside another controller


def enter_realtime(cpu: int | None = None, priority: int = 80, fifo: bool = True) -> RealtimeReport:
    """Pin, raise priority, freeze gc; never raises for lack of privilege."""
    notices = []
    pinned = None
    cpus = sorted(os.sched_getaffinity(0))
    claimed = claim_cpu(cpus) if cpu is None else cpu
    shared = claimed is None
    target = cpus[-1] if claimed is None else claimed
    if shared:
        notices.append(f"CPU {target} shared with another servodesk controller (every core is "
                       "claimed): no warm-up, expect later wake-ups")
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
                          notice="; ".join(notices), shared=shared)


def claim_cpu(cpus: list[int], where: Path | None = None) -> int | None:
    """The highest-numbered of ``cpus`` no other process holds the claim of, claimed for
    this process's life (the lock goes with it, however it ends); None when every one is
    held or none can be claimed. A claim file is opened read-only and never read: one
    another user made is as good a lock as ours, and a symbolic link is refused, as is
    anything but a regular file (a FIFO another user put in its place blocked the controller
    in ``open`` until someone opened it to write: it never started)."""
    where = where or Path(os.environ.get(CLAIMS_ENV, "/dev/shm"))
    for cpu in reversed(cpus):
        try:
            fd = os.open(where / f"servodesk-rt-cpu{cpu}.lock",
                         os.O_RDONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o444)
        except OSError:
            continue
        if stat.S_ISREG(os.fstat(fd).st_mode) and _locked(fd):
            return cpu  # the descriptor stays open (and the lock held) until the process ends
        os.close(fd)
    return None


def _locked(fd: int) -> bool:
    """Whether this process now holds ``fd``'s exclusive lock (False: another one does)."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True
