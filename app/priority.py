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

The controller service (``servodesk controller``) takes the same nice value for its own threads:
while nobody commands, it beats the controller's heartbeat itself. A UI attached to it never
outranks it (``raise_priority_under``): twenty browser sessions at nice -10 beside a service at
0 starved its heartbeat for 4.5 s, the controller held and then stopped (issue 22).
"""

from __future__ import annotations

import contextlib
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


def raise_priority(nice: int = UI_NICE, who: str = "UI") -> Priority:
    """Give the calling thread ``nice`` if that is higher priority than it has; never raises
    for lack of privilege (``who`` names the thread's program in the notice)."""
    thread = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, thread)
    if before <= nice:
        return Priority(thread, before, before)
    try:
        os.setpriority(os.PRIO_PROCESS, thread, nice)
    except OSError as exc:
        return Priority(thread, before, before,
                        f"{who} priority (nice {nice}) refused ({exc.strerror}): a busy machine "
                        "may delay its heartbeat and the controller then holds; allow it with "
                        "CAP_SYS_NICE or a nice limit (ulimit -e)")
    return Priority(thread, before, nice)


def raise_priority_under(service_pid: int) -> Priority:
    """``raise_priority`` for a UI attached to the controller service ``service_pid``: UI_NICE,
    but never a higher priority than the service's (its main thread's nice value). A thread
    that starts above the service is lowered to it; nothing changes when the service is gone."""
    thread = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, thread)
    try:
        nice = max(UI_NICE, os.getpriority(os.PRIO_PROCESS, service_pid))
    except ProcessLookupError:  # the service is gone: the UI says so as its client fails
        return Priority(thread, before, before)
    if before < nice:
        os.setpriority(os.PRIO_PROCESS, thread, nice)  # lowering a priority needs no privilege
        return Priority(thread, before, nice)
    return raise_priority(nice)


def restore(priority: Priority) -> None:
    """Give the thread its nice value back."""
    if priority.now != priority.before:
        # a thread lowered under its service may lack the privilege to go back up
        with contextlib.suppress(PermissionError):
            os.setpriority(os.PRIO_PROCESS, priority.thread, priority.before)
