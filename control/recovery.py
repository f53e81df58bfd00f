"""Runs that died with their savers, saved at the next start — before any clean-up.

A move segment is unlinked only once its run is saved (``control/recorder.py``). So
a move segment whose creating client is dead, and whose controller is dead too (an
orphaned controller saves its client's runs itself, after its loop), holds a run
nobody else will save: the client was killed mid-move or mid-save, or both processes
were. ``recover_runs`` saves each such run where its client saved runs (or, if
that directory cannot take it, in the starting client's), marked ``recovered``
with the status the controller wrote when the move ended (or that it never
ended), clears what a killed save left half done, and unlinks the segment. A run
already saved (its id in a listed run) is only unlinked; a run that can be saved
nowhere now (disk full) stays in its segment for the next start.

Two clients may start at once (the TUI and a script): each segment is recovered by the
one holding an exclusive ``flock`` on its file; the other waits for it (up to ``wait_s``),
so one never clears the half-placed files of the other's save, and when either returns
the run is saved.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from control import shm
from control.run_keeper import FinishedMove, keep

UNENDED = "interrupted: the client and the controller died"


def recover_runs(fallback: Path, wait_s: float = 10.0) -> list[str]:
    """Save every run left in an orphaned move segment (in ``fallback`` if its own directory
    cannot take it); one notice per run or problem. A segment another process is recovering
    is waited for up to ``wait_s``."""
    notices = []
    for name in shm.leftover_segments():
        owner = shm.owner_pid(name)
        if not shm.is_move_segment(name) or owner is None or shm.pid_alive(owner):
            continue
        if not shm.ours(name):
            notices.append(f"left {name} alone: it belongs to another user")
            continue
        with _claimed(name, wait_s) as claimed:
            if claimed is None:
                notice = f"left {name} to the process recovering it (over {wait_s:g} s)"
            else:
                notice = _recover(name, fallback) if claimed else ""
        if notice:
            notices.append(notice)
    return notices


@contextlib.contextmanager
def _claimed(name: str, wait_s: float) -> Iterator[bool | None]:
    """Whether this process may recover segment ``name``: it holds the segment file's
    exclusive lock and the segment is still there (not saved and unlinked by the last
    holder); None if another process held the lock for all of ``wait_s``."""
    path = shm.SHM_DIR / name
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        yield False
        return
    try:
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:  # another start is recovering it: wait for its save
                if time.monotonic() > deadline:
                    yield None
                    return
                time.sleep(0.02)
        yield path.exists()
    finally:
        os.close(fd)  # and with it the lock


def _recover(name: str, fallback: Path) -> str:
    try:
        segment = shm.attach(name)
    except OSError:
        return ""  # gone meanwhile: another start recovered it
    try:
        move = FinishedMove.in_segment(segment)
    except (ValueError, UnicodeDecodeError) as exc:
        shm.release(segment, unlink=True)
        return f"removed {name}: not a move segment this servodesk can read ({exc})"
    try:
        controller = int(move.meta.get("controller_pid", 0))
    except (TypeError, ValueError) as exc:
        shm.release(segment, unlink=False)
        return f"could not recover the run in {name} yet ({exc}); it is kept for the next start"
    if shm.pid_alive(controller):
        shm.release(segment, unlink=False)
        return ""  # its orphaned controller saves it after its loop
    status = f"recovered: {move.status or UNENDED}"
    kept = keep(replace(move, meta={**move.meta, "recovered": True}, status=status),
                fallback=fallback, recovering=True)
    if kept.files is None or kept.run is None:
        return (f"could not recover the run in {name} yet ({kept.problem}); it is kept for "
                "the next start")
    return (f"recovered a {kept.run.kind} run ({kept.run.samples} samples) that a process left "
            f"unsaved when it died: {kept.files.json}")
