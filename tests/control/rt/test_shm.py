"""Segments outlive nobody: orphans of a killed creator are removed at the next start (the
user's own, and never a move segment: control/recovery.py saves its run first); a
segment fits in /dev/shm or is refused, and its pages are reserved when it is made."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from multiprocessing import shared_memory
from pathlib import Path

import pytest

from control.rt import shm


def test_orphan_of_a_killed_process_is_cleaned_up() -> None:
    code = textwrap.dedent("""
        import sys, time
        from control.rt import shm
        seg = shm.create("orphan_test", 4096)
        print(seg.name, flush=True)
        time.sleep(60)
    """)
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                             cwd=os.getcwd())
    try:
        name = child.stdout.readline().strip()
        assert name in shm.leftover_segments()
        assert name not in shm.cleanup_orphans()[0], "a live creator's segment was removed"
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        assert name in shm.leftover_segments(), "kill -9 left nothing behind: nothing to test"
        assert name in shm.cleanup_orphans()[0]
        assert name not in shm.leftover_segments()
    finally:
        child.kill()
        child.wait(10)


def test_names_carry_the_owner_pid() -> None:
    assert shm.owner_pid(shm.segment_name("ctl", pid=1234)) == 1234
    assert shm.owner_pid("psm_abcdef") is None


def dead_pid() -> int:
    """A pid no process can have: the kernel's pid_max itself."""
    return int(Path("/proc/sys/kernel/pid_max").read_text())


def made_by_another_process(name: str, size: int) -> shared_memory.SharedMemory:
    """A segment under ``name`` (another process's pid in it), kept from the tracker."""
    with shm._untracked():
        return shared_memory.SharedMemory(name, create=True, size=size)


def test_a_dead_process_s_move_segment_is_left_for_recovery() -> None:
    name = shm.segment_name("mv1", pid=dead_pid())
    segment = made_by_another_process(name, 4096)
    try:
        assert name not in shm.cleanup_orphans()[0]
        assert name in shm.leftover_segments()
    finally:
        shm.release(segment, unlink=True)


def test_another_user_s_orphan_is_left_alone_with_a_notice() -> None:
    if os.getuid() != 0:
        pytest.skip("making a segment another user's owns needs root (chown)")
    name = shm.segment_name("ctl9", pid=dead_pid())
    segment = made_by_another_process(name, 4096)
    try:
        os.chown(shm.SHM_DIR / name, 65534, 65534)  # nobody
        removed, notices = shm.cleanup_orphans()
        assert name not in removed and name in shm.leftover_segments()
        assert f"left {name} alone: it belongs to another user" in notices
    finally:
        shm.release(segment, unlink=True)


def test_a_segment_larger_than_dev_shm_has_room_for_is_refused_with_both_sizes() -> None:
    too_big = shm.free_bytes() + (1 << 30)
    with pytest.raises(shm.NoRoom, match=r"a test move needs \d+\.\d MB of shared memory and "
                                         r"/dev/shm has \d+\.\d MB free: make the move shorter"):
        shm.create("toobig", too_big, "a test move")
    assert not any("toobig" in n for n in shm.leftover_segments())


def test_a_segment_s_pages_are_reserved_when_it_is_made() -> None:
    before = shm.free_bytes()
    segment = shm.create("reserved", 64 << 20)
    try:
        assert before - shm.free_bytes() >= 60 << 20, "the pages were not reserved"
    finally:
        shm.release(segment, unlink=True)

