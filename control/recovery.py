"""Runs that died with their savers, saved at the next start — before any clean-up — and
the runs a controller handed over as it exited, saved by the saver it started.

A move segment is unlinked only once its run is saved (``control/recorder.py``). So
a move segment whose creating client is dead, and whose controller is dead too, holds a
run nobody else will save: the client was killed mid-move or mid-save, or both processes
were, or the controller handed it over as it exited, its client gone (``control/rt/saver.py``;
its saver, ``main``, saves it as it ended). ``recover_runs`` saves each such run where its
client saved runs (or, if that directory cannot take it, in the starting client's), marked
``recovered`` with the status the controller wrote when the move ended (or that it never
ended) unless it was handed over, clears what a killed save left half done, and unlinks
the segment. A run already saved (its id in a listed run) is only unlinked; a run that can
be saved nowhere now (disk full) stays in its segment for the next start.

Two clients may start at once (the TUI and a script): each segment is recovered by the
one holding an exclusive ``flock`` on its file; the other waits for it (up to ``wait_s``),
so one never clears the half-placed files of the other's save, and when either returns
the run is saved. A move segment of another layout version (a servodesk upgraded while an
older one runs) is left alone: its run is that version's to save.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from control.recorder import default_data_dir
from control.rt import shm
from control.rt.layout import MoveLayout
from control.run_keeper import FinishedMove, keep

UNENDED = "interrupted: the client and the controller died"
AFTER_S = 30.0  # how long a saver waits for its controller to exit


def recover_runs(fallback: Path, wait_s: float = 10.0,
                 names: list[str] | None = None) -> list[str]:
    """Save every run left in an orphaned move segment (of ``names``, if given; in
    ``fallback`` if its own directory cannot take it); one notice per run or problem. A
    segment another process is recovering is waited for up to ``wait_s``."""
    notices = []
    for name in shm.leftover_segments() if names is None else names:
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
    other = MoveLayout.other_version(segment.buf)
    if other is not None:  # an upgrade beside a running older servodesk: its run, not junk
        shm.release(segment, unlink=False)
        return (f"left {name} alone: a run a servodesk of another version wrote (layout "
                f"v{other}); that version saves it when it next starts")
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
        return ""  # its controller keeps it for a client that may come back, then hands it over
    if move.timeline is not None:  # handed over by its controller, its client gone: as it ended
        kept = keep(move, fallback=fallback, recovering=True)
        if kept.files is None or kept.run is None:
            return (f"could not save the run in {name} its client left ({kept.problem}); it is "
                    "kept for the next start")
        return f"saved a run its client left: {kept.files.json}"
    status = f"recovered: {move.status or UNENDED}"
    kept = keep(replace(move, meta={**move.meta, "recovered": True}, status=status),
                fallback=fallback, recovering=True)
    if kept.files is None or kept.run is None:
        return (f"could not recover the run in {name} yet ({kept.problem}); it is kept for "
                "the next start")
    return (f"recovered a {kept.run.kind} run ({kept.run.samples} samples) that a process left "
            f"unsaved when it died: {kept.files.json}")


def main(argv: list[str] | None = None) -> int:
    """``python -m control.recovery --after PID SEGMENT…``: the saver a controller starts as
    it exits with runs its client left (``control/rt/saver.py``): wait for it to be gone, then
    save the runs in those segments. Each notice goes to stderr."""
    parser = argparse.ArgumentParser(prog="python -m control.recovery")
    parser.add_argument("--after", type=int, required=True, metavar="PID",
                        help="the controller to wait for")
    parser.add_argument("segments", nargs="+", help="the move segments it handed over")
    args = parser.parse_args(argv)
    with contextlib.suppress(OSError, AttributeError):  # a real-time parent's class: not ours
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    deadline = time.monotonic() + AFTER_S
    while shm.pid_alive(args.after) and time.monotonic() < deadline:
        time.sleep(0.02)
    for notice in recover_runs(default_data_dir(), names=args.segments):
        print(f"servodesk saver: {notice}", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
