"""Frames on servodesk's sockets (``control/rt/wire.py``) and a move's sealed path
(``control/rt/sealed.py``): data in, never code; every read bounded; a path nobody can change."""

from __future__ import annotations

import mmap
import os
import pickle
import socket
import struct
import time
from collections.abc import Iterator

import numpy as np
import pytest

from control.rt.channel import CODEC, EVENT_LIMIT
from control.rt.commands import FeedOverride, Hold, Manual, StartMove
from control.rt.events import MoveDone
from control.rt.feed import MAX_ENTRIES
from control.rt.modes import TIMELINE_ENTRIES
from control.rt.sealed import NotSealed, open_sealed, seal
from control.rt.wire import HEADER, Broken, Unreadable, Wire


@pytest.fixture
def pair() -> Iterator[tuple[Wire, Wire]]:
    a, b = socket.socketpair()
    ends = Wire(a, CODEC, 1024, frame_s=0.2), Wire(b, CODEC, 1 << 20, frame_s=0.2)
    yield ends
    for end in ends:
        end.close()


def test_records_cross_as_they_were_sent(pair) -> None:
    sender, receiver = pair
    done = MoveDone(7, "complete", 12, gaps=((1.0, 0.5),), feed=((0.0, 1.0), (2.5, 0.5)))
    for record in (Manual((1.0, -2.0, 0.0, 0.0, 0.0, 100.0)), Hold("interrupted: gone"), done):
        sender.send(record)
        assert receiver.recv().record == record


def test_a_pickle_is_no_record_and_runs_nothing(pair, tmp_path) -> None:
    sender, receiver = pair
    marker = tmp_path / "ran"

    class Boom:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    sender.send_bytes(pickle.dumps(Boom()))
    with pytest.raises(Unreadable, match="not JSON"):
        receiver.recv()
    sender.send(Hold())  # the stream goes on after an unreadable message
    assert receiver.recv().record == Hold()
    assert not marker.exists()


@pytest.mark.parametrize(("body", "says"), [
    (b'{"type": "Popen", "fields": {}}', "'Popen' is not a record"),
    (b'{"type": "Hold", "fields": {"reason": "x", "extra": 1}}', "no field 'extra'"),
    (b'{"type": "FeedOverride", "fields": {"value": 2.0}}', "must be in 0"),
    (b'[1, 2]', "not a record"),
    (b"[" * 100_000 + b"]" * 100_000, "not JSON"),
])
def test_a_whole_frame_that_is_no_good_record_is_unreadable(body: bytes, says: str) -> None:
    a, b = socket.socketpair()
    sender, receiver = Wire(a, CODEC, 1 << 20), Wire(b, CODEC, 1 << 20)
    try:
        sender.send_bytes(body)
        with pytest.raises(Unreadable, match=says):
            receiver.recv()
    finally:
        sender.close()
        receiver.close()


def test_a_frame_over_the_limit_is_refused_before_it_is_read(pair) -> None:
    receiver, sender = pair  # the first end takes 1 KiB at most
    sender.sock.sendall(HEADER.pack(2**31))  # says 2 GiB follow, sends nothing more
    with pytest.raises(Broken, match="over this link's limit of 1024"):
        receiver.recv()


def test_a_frame_cut_short_breaks_the_stream_in_time(pair) -> None:
    sender, receiver = pair
    receiver.frame_s = 0.02  # the pair's 0.2 s was waited out idle
    sender.sock.sendall(HEADER.pack(100) + b'{"type"')
    started = time.monotonic()
    with pytest.raises(Broken, match="cut short"):
        receiver.recv()
    assert time.monotonic() - started < 5.0


def test_a_closed_peer_is_a_broken_stream(pair) -> None:
    sender, receiver = pair
    sender.close()
    with pytest.raises(Broken):
        receiver.recv()


def test_a_sealed_path_crosses_with_its_command_and_cannot_be_written(pair) -> None:
    sender, receiver = pair
    rows = np.arange(12.0).reshape(2, 6)
    fd = seal(rows)
    sender.send(StartMove(1, "sd_1_mv1", "path", False, 2), (fd,))
    os.close(fd)
    message = receiver.recv()
    assert message.record.samples == 2 and len(message.fds) == 1
    (received,) = message.fds
    path = open_sealed(received, rows.nbytes)
    try:
        assert np.array_equal(np.frombuffer(path, np.float64).reshape(2, 6), rows)
        with pytest.raises(PermissionError):
            os.pwrite(received, struct.pack("<d", 60.0), 8)
        with pytest.raises(PermissionError):
            mmap.mmap(received, rows.nbytes)  # a writable, shared mapping
        with pytest.raises(PermissionError):
            os.ftruncate(received, 0)
    finally:
        path.close()
        message.close_fds()


def test_a_path_that_is_not_sealed_or_not_the_moves_is_refused() -> None:
    loose = os.memfd_create("loose", os.MFD_ALLOW_SEALING)
    sealed = seal(np.zeros((3, 6)))
    try:
        os.write(loose, bytes(144))
        with pytest.raises(NotSealed, match="not sealed against writing"):
            open_sealed(loose, 144)
        with pytest.raises(NotSealed, match="holds 144 bytes, the move 288"):
            open_sealed(sealed, 288)
        with pytest.raises(NotSealed, match="no sealed path came with the move"):
            open_sealed(-1, 144)
    finally:
        os.close(loose)
        os.close(sealed)


def test_commands_keep_their_checks_through_the_wire(pair) -> None:
    sender, receiver = pair
    sender.send_bytes(CODEC.encode(FeedOverride(0.5)).replace(b"0.5", b"NaN"))
    with pytest.raises(Unreadable, match="finite"):
        receiver.recv()


def test_a_move_done_with_every_timeline_full_fits_its_frame() -> None:
    """The controller bounds a move's timelines so its MoveDone always crosses the channel: a
    frame over the client's bound would break it, and the client would take the controller
    for dead."""
    long = tuple((123456.7891, 12345.6789) for _ in range(TIMELINE_ENTRIES))
    feed = tuple((123456.7891, 0.123456789) for _ in range(MAX_ENTRIES))
    done = MoveDone(10**9, "x" * 256, 10**9, saved="/" * 4096, gaps=long, feed=feed, pauses=feed,
                    supply=long)
    assert len(CODEC.encode(done)) < EVENT_LIMIT
