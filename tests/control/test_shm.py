"""Segments outlive nobody: orphans of a killed creator are removed at the next start."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

from control import shm


def test_orphan_of_a_killed_process_is_cleaned_up() -> None:
    code = textwrap.dedent("""
        import sys, time
        from control import shm
        seg = shm.create("orphan_test", 4096)
        print(seg.name, flush=True)
        time.sleep(60)
    """)
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                             cwd=os.getcwd())
    try:
        name = child.stdout.readline().strip()
        assert name in shm.leftover_segments()
        assert name not in shm.cleanup_orphans(), "a live creator's segment was removed"
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        assert name in shm.leftover_segments(), "kill -9 left nothing behind: nothing to test"
        assert name in shm.cleanup_orphans()
        assert name not in shm.leftover_segments()
    finally:
        child.kill()
        child.wait(10)


def test_names_carry_the_owner_pid() -> None:
    assert shm.owner_pid(shm.segment_name("ctl", pid=1234)) == 1234
    assert shm.owner_pid("psm_abcdef") is None
