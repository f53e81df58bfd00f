"""The operator's console outranks other work on the machine, while it runs.

The TUI carries the operator's E-stop key and the client's heartbeat: if it waits for a
CPU for a quarter of a second, the controller holds the robot ("client silent"). On a
shared two-core machine with a busy neighbour (a CPU burner in the tests) the UI waited
100-200 ms for a CPU at a time while its own work was 20-70 ms (``benchmarks/ui.py
--pauses``). So the UI's thread takes a nice value of ``UI_NICE`` as it loads, before it
starts the controller's client, the terminal's input reader or any worker: on Linux the
nice value is per thread and inherited by the threads and processes a thread starts, so
the heartbeat thread, the input thread and the controller (until it takes SCHED_FIFO)
have it too. It is given back when the app ends (raising a nice value needs no
privilege), so a test process that runs the app goes on at its own priority.

Where the OS refuses (no root, no CAP_SYS_NICE, no ``ulimit -e``), the UI runs at its
normal priority and says so, like the controller's SCHED_FIFO notice.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

UI_NICE = -10  # CFS weight 9548 against a nice-0 neighbour's 1024: the UI rarely waits


@dataclass(frozen=True)
class Priority:
    """The nice value a thread had (``before``) and has (``now``); ``notice`` says why it
    could not be raised."""

    thread: int
    before: int
    now: int
    notice: str = ""


def raise_priority(nice: int = UI_NICE) -> Priority:
    """Give the calling thread ``nice`` if that is higher priority than it has; never raises
    for lack of privilege."""
    thread = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, thread)
    if before <= nice:
        return Priority(thread, before, before)
    try:
        os.setpriority(os.PRIO_PROCESS, thread, nice)
    except OSError as exc:
        return Priority(thread, before, before,
                        f"UI priority (nice {nice}) refused ({exc.strerror}): a busy machine may "
                        "delay its heartbeat and the controller then holds; allow it with "
                        "CAP_SYS_NICE or a nice limit (ulimit -e)")
    return Priority(thread, before, nice)


def restore(priority: Priority) -> None:
    """Give the thread its nice value back (only ever lowering its priority)."""
    if priority.now != priority.before:
        os.setpriority(os.PRIO_PROCESS, priority.thread, priority.before)
