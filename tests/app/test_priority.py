"""The UI's thread takes a higher CPU priority while the app runs and gives it back; where the
OS refuses, it says so and runs on; a UI attached to a controller service never outranks the
service (a thread of this process stands for the service's main thread: a nice value is per
thread, and read by its id as a process's is). Nice values are read back from the OS."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from app.priority import UI_NICE, Priority, raise_priority, raise_priority_under, restore

ROOT = Path(__file__).resolve().parents[2]


def in_a_thread(work) -> object:
    """Run ``work`` in a fresh thread (the nice value is per thread on Linux: this test's own
    thread keeps its priority) and return what it returned."""
    out: list[object] = []
    thread = threading.Thread(target=lambda: out.append(work()))
    thread.start()
    thread.join()
    return out[0]


def nice_of(thread: int) -> int:
    return os.getpriority(os.PRIO_PROCESS, thread)


@contextmanager
def service_at(nice: int) -> Iterator[int]:
    """A thread at ``nice`` while the block runs, standing for a service's main thread; its
    id."""
    ready, done = threading.Event(), threading.Event()
    ids: list[int] = []

    def wait() -> None:
        ids.append(threading.get_native_id())
        os.setpriority(os.PRIO_PROCESS, ids[0], nice)
        ready.set()
        done.wait()

    thread = threading.Thread(target=wait)
    thread.start()
    ready.wait()
    try:
        yield ids[0]
    finally:
        done.set()
        thread.join()


def attached_to(service: int) -> tuple[Priority, int]:
    """A UI thread's priority under ``service``, and its nice value read back."""
    def work() -> tuple[Priority, int]:
        taken = raise_priority_under(service)
        return taken, nice_of(taken.thread)

    return in_a_thread(work)


@pytest.mark.skipif(os.geteuid() != 0, reason="raising a priority needs root or CAP_SYS_NICE; "
                    "the refusal is tested below")
def test_the_ui_thread_is_raised_and_given_back() -> None:
    def work() -> tuple[Priority, int, int]:
        raised = raise_priority()
        during = nice_of(raised.thread)
        restore(raised)
        return raised, during, nice_of(raised.thread)

    raised, during, after = in_a_thread(work)
    assert raised.notice == "" and raised.now == during == UI_NICE
    assert after == raised.before


def test_a_thread_already_above_it_is_left_alone() -> None:
    def work() -> tuple[Priority, int]:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 15)  # lowering: always allowed
        return raise_priority(nice=19), nice_of(threading.get_native_id())

    left, nice = in_a_thread(work)
    assert left.before == left.now == nice == 15 and left.notice == ""


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) drops the "
                    "capability to raise priority")
def test_without_the_privilege_the_ui_says_so_and_runs_at_its_own_priority() -> None:
    """A process without CAP_SYS_NICE (setpriv drops it, so root is refused too) and with a
    nice limit of 0."""
    script = ("import json, os, threading; from app.priority import raise_priority; "
              "p = raise_priority(); "
              "print(json.dumps([p.before, p.now, p.notice, "
              "os.getpriority(os.PRIO_PROCESS, threading.get_native_id())]))")
    done = subprocess.run(
        ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice", "--",
         "prlimit", "--nice=0", sys.executable, "-c", script],
        capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=60, check=True)
    before, now, notice, nice = json.loads(done.stdout)
    assert before == now == nice
    assert "refused" in notice and "ulimit -e" in notice


def test_an_attached_ui_takes_no_higher_priority_than_a_service_that_has_less_than_it() -> None:
    with service_at(5) as service:  # lowering: always allowed
        taken, nice = attached_to(service)
    assert taken.now == nice == 5  # lowered from this test's own, not raised to UI_NICE


@pytest.mark.skipif(os.geteuid() != 0, reason="a service above nice 0 needs root or "
                    "CAP_SYS_NICE")
@pytest.mark.parametrize(("service", "ui"), [(UI_NICE, UI_NICE), (UI_NICE - 5, UI_NICE)])
def test_an_attached_ui_takes_its_own_priority_under_a_service_at_or_above_it(service, ui
                                                                              ) -> None:
    with service_at(service) as pid:
        taken, nice = attached_to(pid)
    assert taken.now == nice == ui and taken.notice == ""


def test_an_attached_ui_whose_service_is_gone_keeps_its_priority() -> None:
    with service_at(0) as gone:
        pass
    taken, nice = attached_to(gone)
    assert taken.before == taken.now == nice
