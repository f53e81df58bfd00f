"""The seqlock never hands a reader a torn record, with the writer in another process."""

from __future__ import annotations

import multiprocessing as mp
import struct
import time

from control.rt import shm
from control.rt.seqlock import SeqlockReader, SeqlockWriter

RECORD = struct.Struct("<64q")
WRITES = 1_000_000


def _writer(name: str, count: int) -> None:
    segment = shm.attach(name)
    writer = SeqlockWriter(segment.buf, 0, RECORD)
    for i in range(1, count + 1):
        writer.write(*([i] * 64))
    writer.release()
    shm.release(segment, unlink=False)


def test_reader_never_sees_a_torn_record() -> None:
    segment = shm.create("seqlock_test", 8 + RECORD.size)
    reader = SeqlockReader(segment.buf, 0, RECORD)
    process = mp.get_context("spawn").Process(target=_writer, args=(segment.name, WRITES))
    process.start()
    try:
        seen = set()
        deadline = time.monotonic() + 60.0
        while process.is_alive() and time.monotonic() < deadline:
            values = reader.read(patience_s=10.0)
            assert len(set(values)) == 1, f"torn record: {sorted(set(values))[:4]}"
            seen.add(values[0])
        midway = {v for v in seen if 0 < v < WRITES}
        assert len(midway) >= 10, "no reads overlapped the writes; the test proved nothing"
    finally:
        process.join(5)
        reader.release()
        shm.release(segment, unlink=True)


def test_unaligned_offset_is_refused() -> None:
    buf = memoryview(bytearray(64))
    try:
        SeqlockWriter(buf, 4, struct.Struct("<q"))
    except ValueError as exc:
        assert "aligned" in str(exc)
    else:
        raise AssertionError("an unaligned seqlock was accepted")
