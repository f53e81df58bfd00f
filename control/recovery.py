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
"""

from __future__ import annotations

from pathlib import Path

from control import shm
from control.layout import MoveLayout
from control.recorder import (
    RecorderError,
    find_run,
    remove_incomplete,
    remove_stale_temps,
    save_run,
)
from control.runs import decode_meta, run_from_segment

UNENDED = "interrupted: the client and the controller died"


def recover_runs(fallback: Path) -> list[str]:
    """Save every run left in an orphaned move segment (in ``fallback`` if its own directory
    cannot take it); one notice per run or problem."""
    notices = []
    for name in shm.leftover_segments():
        owner = shm.owner_pid(name)
        if not shm.is_move_segment(name) or owner is None or shm.pid_alive(owner):
            continue
        if not shm.ours(name):
            notices.append(f"left {name} alone: it belongs to another user")
            continue
        notice = _recover(name, fallback)
        if notice:
            notices.append(notice)
    return notices


def _recover(name: str, fallback: Path) -> str:
    try:
        segment = shm.attach(name)
    except OSError:
        return ""  # gone meanwhile: another start recovered it
    unlink = False
    try:
        try:
            layout = MoveLayout.read_header(segment.buf)
            meta = decode_meta(layout.read_meta(segment.buf))
        except (ValueError, UnicodeDecodeError) as exc:
            unlink = True
            return f"removed {name}: not a move segment this servodesk can read ({exc})"
        if shm.pid_alive(int(meta.get("controller_pid", 0))):
            return ""  # its orphaned controller saves it after its loop
        data_dir = Path(str(meta["data_dir"]))
        status = f"recovered: {layout.read_status(segment.buf) or UNENDED}"
        run = run_from_segment(segment.buf, layout, {**meta, "recovered": True}, status)
        saved = find_run(data_dir, run) or find_run(fallback, run)
        if saved is None:
            remove_incomplete(data_dir, run)
            remove_stale_temps(data_dir, shm.pid_alive)
            try:
                saved = save_run(run, data_dir)
            except RecorderError:
                saved = save_run(run, fallback)
        unlink = True
        return (f"recovered a {run.kind} run ({run.samples} samples) that a process left "
                f"unsaved when it died: {saved.json}")
    except (RecorderError, KeyError, TypeError, ValueError) as exc:
        return f"could not recover the run in {name} yet ({exc}); it is kept for the next start"
    finally:
        shm.release(segment, unlink=unlink)
