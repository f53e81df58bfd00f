"""Named shared-memory segments with servodesk's own lifetime rules.

Python 3.11's resource tracker unlinks a segment when *any* process that
attached to it exits, and cleans up nothing after ``kill -9`` of the creator.
So no segment is ever registered with it (3.13's ``track=False``, done by
hand) and servodesk owns its cleanup: names carry the creating process's
pid (``sd_<pid>_<tag>_<random>``), the creator unlinks on every exit path, and
``cleanup_orphans`` removes segments whose creator is dead at the next start:
the user's own only, and never a move segment (its run may be unsaved:
``control/recovery.py`` saves it first and unlinks it itself).

A segment fits or is refused: before one is created the space left in /dev/shm
is checked, and its pages are reserved at once (``posix_fallocate``), so no
later write to it can fault (a bus error, on a full tmpfs, kills the process).
"""

from __future__ import annotations

import _posixshmem
import contextlib
import errno
import os
import secrets
import threading
from collections.abc import Iterator
from multiprocessing import resource_tracker, shared_memory
from pathlib import Path

PREFIX = "sd_"
SHM_DIR = Path("/dev/shm")


def segment_name(tag: str, pid: int | None = None) -> str:
    return f"{PREFIX}{os.getpid() if pid is None else pid}_{tag}"


class NoRoom(OSError):
    """/dev/shm cannot hold a segment (ENOSPC); the message gives both sizes and the fix."""

    def __init__(self, message: str) -> None:
        super().__init__(errno.ENOSPC, message)

    def __str__(self) -> str:
        return str(self.strerror)


def create(tag: str, size: int, what: str = "this") -> shared_memory.SharedMemory:
    """Create a zero-filled segment named for this process and ``tag``, its pages reserved;
    ``NoRoom`` if /dev/shm has no room for it (``what`` names it in the message). The name
    ends in a random part: another user who made ``sd_<pid>_ctl1`` as this process started
    (its pid is public, its names were not) made its every start fail (FileExistsError)."""
    size = max(size, 8)
    free = free_bytes()
    if size > free:
        raise _no_room(what, size, free)
    with _untracked():
        segment = shared_memory.SharedMemory(segment_name(f"{tag}_{secrets.token_hex(8)}"),
                                             create=True, size=size)
    try:
        os.posix_fallocate(segment._fd, 0, size)  # type: ignore[attr-defined]
    except OSError as exc:
        release(segment, unlink=True)
        raise _no_room(what, size, free_bytes()) from exc
    return segment


def free_bytes() -> int:
    """Bytes /dev/shm can still give (unlimited where there is no such directory)."""
    try:
        stat = os.statvfs(SHM_DIR)
    except OSError:
        return 1 << 62
    return stat.f_bavail * stat.f_frsize


def _no_room(what: str, size: int, free: int) -> NoRoom:
    return NoRoom(f"{what} needs {size / 1e6:.1f} MB of shared memory and {SHM_DIR} has "
                  f"{free / 1e6:.1f} MB free: make the move shorter, or give {SHM_DIR} more "
                  "room (e.g. docker run --shm-size=1g)")


def attach(name: str) -> shared_memory.SharedMemory:
    """Attach to an existing segment without letting the resource tracker adopt it."""
    with _untracked():
        return shared_memory.SharedMemory(name)


def release(shm: shared_memory.SharedMemory, unlink: bool) -> None:
    """Close (and optionally unlink) a segment; already-gone segments are fine."""
    with contextlib.suppress(BufferError):
        shm.close()
    if unlink:
        with contextlib.suppress(FileNotFoundError):
            _posixshmem.shm_unlink(shm._name)  # type: ignore[attr-defined]  # tracker-free unlink


def owner_pid(name: str) -> int | None:
    if not name.startswith(PREFIX):
        return None
    head = name[len(PREFIX):].split("_", 1)[0]
    return int(head) if head.isdigit() else None


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` still runs. An exited one not yet reaped (a zombie: its parent
    gone, a lazy init) does not: it holds no memory and never runs again, and a saver
    waiting for it (``control/recovery.py``) waited until the reaping, 1.6 s in a VM."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:  # no procfs, or reaped meanwhile: os.kill's answer stands
        return True
    return stat[stat.rfind(b")") + 2:][:1] not in (b"Z", b"X")


def leftover_segments() -> list[str]:
    """Names of every servodesk segment present, live or not."""
    if not SHM_DIR.is_dir():
        return []
    return sorted(p.name for p in SHM_DIR.iterdir() if p.name.startswith(PREFIX))


def is_move_segment(name: str) -> bool:
    return name.split("_", 2)[-1].startswith("mv")


def ours(name: str) -> bool:
    """Whether this user owns segment ``name`` (gone: False). The entry itself is judged, never
    what it links to: another user's symbolic link to a file of ours (``/proc/self/status``
    is everyone's own) is theirs, and unlinking it in the sticky /dev/shm fails."""
    try:
        return (SHM_DIR / name).lstat().st_uid == os.getuid()
    except OSError:
        return False


def cleanup_orphans() -> tuple[list[str], list[str]]:
    """Unlink this user's segments whose creating process no longer exists, except move
    segments (``control/recovery.py`` deals with those); (names removed, notices)."""
    removed, notices = [], []
    for name in leftover_segments():
        pid = owner_pid(name)
        if pid is None or pid_alive(pid) or is_move_segment(name):
            continue
        if not ours(name):
            notices.append(f"left {name} alone: it belongs to another user")
            continue
        with contextlib.suppress(FileNotFoundError):
            (SHM_DIR / name).unlink()
            removed.append(name)
    return removed, notices


_TRACKER_LOCK = threading.Lock()


@contextlib.contextmanager
def _untracked() -> Iterator[None]:
    """Keep ``SharedMemory`` from registering with the resource tracker (3.13's track=False).

    Registering would also start the tracker process, which needs a real stderr
    (a Textual app has none) and would unlink segments behind our back.
    """
    with _TRACKER_LOCK:
        register = resource_tracker.register
        resource_tracker.register = lambda name, rtype: None
        try:
            yield
        finally:
            resource_tracker.register = register
