"""A move's path, sealed: written once by the client that plans it, then unwritable by anyone.

The desired path (or duty profile) of a move is put in an anonymous memory file
(``memfd_create``) and sealed against writing, shrinking and growing before it is sent:
the kernel then refuses every write to it, from any process, the client's own included.
It has no name in /dev/shm; its descriptor travels with the ``StartMove`` command
(``control/rt/wire.py``), through a controller service too, and the controller maps it
read-only after checking its seals and size. So what the controller follows is exactly
what the commanding client sent, whoever else can write this user's shared memory.
"""

from __future__ import annotations

import fcntl
import mmap
import os

import numpy as np

SEALS = fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL


class NotSealed(ValueError):
    """A path descriptor that is not a sealed memory file of the expected size."""


def seal(rows: np.ndarray) -> int:
    """A descriptor of a sealed memory file holding ``rows`` as float64 (the caller closes it)."""
    data = np.ascontiguousarray(rows, dtype=np.float64)
    fd = os.memfd_create("servodesk-path", os.MFD_ALLOW_SEALING | os.MFD_CLOEXEC)
    try:
        view = memoryview(data).cast("B")
        written = 0
        while written < len(view):
            written += os.write(fd, view[written:])
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, SEALS)
    except BaseException:
        os.close(fd)
        raise
    return fd


def open_sealed(fd: int, size: int) -> mmap.mmap:
    """Map the sealed file ``fd`` read-only, ``NotSealed`` unless it is sealed against every
    change and holds exactly ``size`` bytes. ``fd`` stays the caller's."""
    if fd < 0:
        raise NotSealed("no sealed path came with the move: send it with StartMove")
    try:
        seals = fcntl.fcntl(fd, fcntl.F_GET_SEALS)
    except OSError as exc:
        raise NotSealed(f"the path is not a sealed memory file ({exc.strerror})") from None
    if seals & SEALS != SEALS:
        raise NotSealed("the path is not sealed against writing: refused")
    actual = os.fstat(fd).st_size
    if actual != size:
        raise NotSealed(f"the path holds {actual} bytes, the move {size}")
    return mmap.mmap(fd, size, prot=mmap.PROT_READ)
