"""Named shared-memory segments with servodesk's own lifetime rules.

Python 3.11's resource tracker unlinks a segment when *any* process that
attached to it exits, and cleans up nothing after ``kill -9`` of the creator.
So no segment is ever registered with it (3.13's ``track=False``, done by
hand) and servodesk owns its cleanup: names carry the creating process's
pid (``sd_<pid>_<tag>``), the creator unlinks on every exit path, and
``cleanup_orphans`` removes segments whose creator is dead at the next start.
"""

from __future__ import annotations

import _posixshmem
import contextlib
import os
import threading
from collections.abc import Iterator
from multiprocessing import resource_tracker, shared_memory
from pathlib import Path

PREFIX = "sd_"
SHM_DIR = Path("/dev/shm")


def segment_name(tag: str, pid: int | None = None) -> str:
    return f"{PREFIX}{os.getpid() if pid is None else pid}_{tag}"


def create(tag: str, size: int) -> shared_memory.SharedMemory:
    """Create a zero-filled segment named for this process and ``tag``."""
    with _untracked():
        return shared_memory.SharedMemory(segment_name(tag), create=True, size=max(size, 8))


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
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def leftover_segments() -> list[str]:
    """Names of every servodesk segment present, live or not."""
    if not SHM_DIR.is_dir():
        return []
    return sorted(p.name for p in SHM_DIR.iterdir() if p.name.startswith(PREFIX))


def cleanup_orphans() -> list[str]:
    """Unlink segments whose creating process no longer exists; return their names."""
    removed = []
    for name in leftover_segments():
        pid = owner_pid(name)
        if pid is not None and not pid_alive(pid):
            with contextlib.suppress(FileNotFoundError):
                (SHM_DIR / name).unlink()
                removed.append(name)
    return removed


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
