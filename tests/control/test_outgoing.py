"""A client's outgoing commands (``control/outgoing.py``): on the wire from the caller's
thread when the socket takes them, queued in order behind anything that waits when it does
not, never waiting on the wire, and descriptors closed once sent or dropped."""

from __future__ import annotations

import os
import queue
import socket
import threading
from collections.abc import Iterator

import pytest

from control.outgoing import Outgoing
from control.rt.channel import CODEC, COMMAND_LIMIT
from control.rt.commands import Hold
from control.rt.wire import Message, Wire

LIMIT = 8


@pytest.fixture
def ends() -> Iterator[tuple[Wire, Wire]]:
    ours, theirs = socket.socketpair()
    ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # full after a few frames
    pair = Wire(ours, CODEC, 1 << 20), Wire(theirs, CODEC, COMMAND_LIMIT)
    yield pair
    for end in pair:
        end.close()


def closed(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return True
    return False


def test_a_command_is_on_the_wire_when_put_returns_with_no_sender_thread(ends) -> None:
    client, controller = ends
    outgoing = Outgoing(client, LIMIT)
    read, write = os.pipe()
    os.close(write)
    outgoing.put_nowait(Message(Hold("now"), (read,)))
    assert controller.poll()
    message = controller.recv()
    assert message.record == Hold("now") and len(message.fds) == 1
    message.close_fds()
    assert closed(read)  # sent: the client's copy is closed


def test_commands_the_wire_cannot_take_wait_in_order_and_none_is_lost(ends) -> None:
    """The controller does not read: puts go on returning until ``LIMIT`` wait, then refuse
    (``queue.Full``); once it reads, the sender thread delivers every one accepted, in order,
    behind the frame the socket took a part of."""
    client, controller = ends
    outgoing = Outgoing(client, LIMIT)
    accepted = []
    with pytest.raises(queue.Full):
        for n in range(10_000):
            outgoing.put_nowait(Message(Hold(f"{n:04d}" + "x" * 190)))
            accepted.append(n)
    assert len(accepted) > LIMIT  # some went on the wire at once
    sender = threading.Thread(target=outgoing.run, daemon=True)
    sender.start()
    received = [int(controller.recv().record.reason[:4]) for _ in accepted]
    assert received == accepted
    outgoing.put_nowait(Message(Hold("after")))  # the queue empty again: straight out
    assert controller.recv().record == Hold("after")
    outgoing.close()
    sender.join(timeout=5)
    assert not sender.is_alive()


def test_commands_dropped_unsent_have_their_descriptors_closed(ends) -> None:
    client, _ = ends
    outgoing = Outgoing(client, LIMIT)
    fds = []
    with pytest.raises(queue.Full):
        for _ in range(10_000):
            read, write = os.pipe()
            os.close(write)
            fds.append(read)
            outgoing.put_nowait(Message(Hold("x" * 200), (read,)))
    outgoing.drop()
    assert all(closed(fd) for fd in fds)
