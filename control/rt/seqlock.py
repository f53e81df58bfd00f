"""A single-writer seqlock over shared memory, so a reader never sees a torn record.

The writer makes the sequence counter odd, packs the record, then makes it
even again. A reader copies the record between two reads of the counter and
retries if they differ or are odd. The counter is one aligned 8-byte store
through a typed memoryview (a byte-wise pack was measured to tear).
"""

from __future__ import annotations

import os
import struct
import time


class SeqlockWriter:
    """Publishes one fixed-layout record; called every tick, allocates nothing of its own."""

    def __init__(self, buf: memoryview, offset: int, record: struct.Struct) -> None:
        if offset % 8:
            raise ValueError(f"seqlock offset {offset} is not 8-byte aligned")
        self._seq = buf[offset:offset + 8].cast("Q")
        self._buf = buf
        self._offset = offset + 8
        self._pack = record.pack_into
        self._count = self._seq[0] & ~1

    def write(self, *values: object) -> None:
        count = self._count + 1
        self._seq[0] = count
        self._pack(self._buf, self._offset, *values)
        self._count = count + 1
        self._seq[0] = count + 1

    def release(self) -> None:
        self._seq.release()


class SeqlockReader:
    """Takes consistent snapshots of a record written by a ``SeqlockWriter``."""

    def __init__(self, buf: memoryview, offset: int, record: struct.Struct) -> None:
        self._seq = buf[offset:offset + 8].cast("Q")
        self._body = buf[offset + 8:offset + 8 + record.size]
        self._record = record

    def read(self, patience_s: float = 1.0) -> tuple:
        """Return the newest complete record; raise TimeoutError if the writer never settles."""
        deadline = time.monotonic() + patience_s
        attempt = 0
        while True:
            before = self._seq[0]
            if not before & 1:
                data = bytes(self._body)
                if self._seq[0] == before:
                    return self._record.unpack(data)
            attempt += 1
            if attempt % 64 == 0:
                if time.monotonic() > deadline:
                    raise TimeoutError("seqlock: the writer held the record for the whole read")
                os.sched_yield()  # let a preempted writer finish its record

    @property
    def sequence(self) -> int:
        return self._seq[0]

    def release(self) -> None:
        self._seq.release()
        self._body.release()
