"""The client's threads keep off its controller's core (control/off_core.py), on this process's
real affinity: every thread, those made later too, until the last controller there is gone."""

from __future__ import annotations

import os
import threading

import pytest

from control.off_core import come_back, controller_core, keep_off

pytestmark = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2,
                                reason="one core: there is no other to keep to")


def thread_cores() -> dict[int, set[int]]:
    return {int(t): os.sched_getaffinity(int(t)) for t in os.listdir("/proc/self/task")}


def test_every_thread_keeps_off_the_core_until_its_last_controller_is_gone() -> None:
    before = os.sched_getaffinity(0)
    core = max(before)
    stop = threading.Event()
    earlier = threading.Thread(target=stop.wait)
    earlier.start()
    try:
        assert keep_off(core) and keep_off(core)  # two controllers on it
        assert all(core not in cores for cores in thread_cores().values()), thread_cores()
        later: list[set[int]] = []
        made = threading.Thread(target=lambda: later.append(os.sched_getaffinity(0)))
        made.start()
        made.join()
        assert later == [before - {core}]  # inherited from the thread that made it
        come_back(core)
        assert core not in os.sched_getaffinity(0)  # the other is still there
        come_back(core)
        assert all(core in cores for cores in thread_cores().values()), thread_cores()
    finally:
        stop.set()
        earlier.join()
        os.sched_setaffinity(0, before)


def test_the_last_core_left_is_kept() -> None:
    before = os.sched_getaffinity(0)
    core, other = max(before), min(before)
    try:
        assert keep_off(core)
        assert not keep_off(other)  # it would leave this thread no core: nothing changes
        assert os.sched_getaffinity(0) == before - {core}
        come_back(core)
        assert os.sched_getaffinity(0) == before
    finally:
        os.sched_setaffinity(0, before)


def test_a_controller_pinned_to_one_core_is_found_and_one_not_pinned_is_not() -> None:
    assert controller_core(os.getpid()) is None  # this process may use every core
    assert controller_core(2**22 + 1) is None  # no such process
