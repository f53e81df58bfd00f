"""Files a user names (machine, coefficient, positions, path, pose and run files): only a
regular file is read, as UTF-8 text with or without a byte-order mark.

A named pipe blocks its reader until something writes to it (for ever, if nothing does), a
device may never end (``/dev/zero``) or wait for input (a terminal), a directory or a socket
holds no text: each is refused at once, the message naming the file and what it is. The
file is opened without waiting and only then asked what it is (``fstat``), so a path that
becomes a FIFO between a check and the open cannot hang the reader either.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import BinaryIO

# Windows editors (Notepad, Excel's "CSV UTF-8") start a UTF-8 file with a byte-order mark;
# this codec drops one there and decodes the rest as UTF-8.
TEXT_ENCODING = "utf-8-sig"

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


class NotRegularFile(OSError):
    """A path that names something other than a regular file; ``kind`` says what it is
    ("a named pipe (FIFO)")."""

    def __init__(self, path: Path, kind: str) -> None:
        super().__init__(errno.EINVAL, f"not a regular file but {kind}", str(path))
        self.kind = kind


def open_regular(path: Path) -> BinaryIO:
    """``path`` opened for reading in binary; NotRegularFile at once if it is not a regular
    file, other OSErrors (missing, no permission) as ``open`` raises them."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # a FIFO: no wait
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFile(path, file_kind(mode))
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words: "a named pipe (FIFO)"."""
    return next((kind for test, kind in _KINDS if test(mode)), "a special file")
