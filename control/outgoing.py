"""A client's commands on their way to the wire: in order, and no caller ever waits on it.

``put`` sends a command from the caller's own thread when nothing is ahead of it and the
socket takes the whole frame at once (the usual case: a command is a few hundred bytes and
the controller reads every tick). Otherwise the frame, or the rest of it, waits here for
the link's sender thread (``run``), which alone waits on the wire. Handing every command to
that thread cost as long as the caller kept the GIL: up to Python's switch interval (5 ms)
while it ran Python, a UI redrawing or a script polling the status.
"""

from __future__ import annotations

import queue
import threading
from collections import deque
from dataclasses import dataclass

from control.rt.wire import Broken, Message, Wire


@dataclass(frozen=True)
class Frame:
    """Bytes still to send, and the descriptors to pass with the first of them."""

    data: bytes
    fds: tuple[int, ...] = ()

    def close_fds(self) -> None:
        Message(None, self.fds).close_fds()


class Outgoing:
    """Frames for ``wire``, oldest first; at most ``limit`` wait (``queue.Full`` past that:
    the other end is frozen or flooded). The descriptors sent with a command are closed once
    they have gone, or when it is dropped."""

    def __init__(self, wire: Wire, limit: int) -> None:
        self.wire = wire
        self.limit = limit
        self._waiting: deque[Frame] = deque()
        self._changed = threading.Condition()
        self._busy = False  # the sender thread is writing a frame it took
        self._broken = False  # the wire failed: nothing more goes out
        self._closing = False

    def put_nowait(self, message: Message) -> None:
        """Send ``message`` now if the wire takes it, else queue it; ``queue.Full`` when the
        last ``limit`` still wait."""
        self._put(message, block=False)

    def put(self, message: Message) -> None:
        """As ``put_nowait``, but wait for room rather than raise."""
        self._put(message, block=True)

    def _put(self, message: Message, block: bool) -> None:
        try:
            frame = Frame(self.wire.frame(message.record), message.fds)
        except BaseException:
            message.close_fds()
            raise
        with self._changed:
            if not (self._waiting or self._busy or self._broken):
                frame = self._offer(frame)
                if not frame.data:
                    return
            while len(self._waiting) >= self.limit:
                if not block:
                    frame.close_fds()
                    raise queue.Full
                if self._broken or self._closing:  # nobody will ever send it
                    frame.close_fds()
                    return
                self._changed.wait()
            self._waiting.append(frame)
            self._changed.notify_all()

    def _offer(self, frame: Frame) -> Frame:
        """What of ``frame`` the wire did not take at once (its descriptors gone with its
        first byte); on a broken wire, all of it, and nothing more is tried."""
        try:
            sent = self.wire.offer(frame.data, frame.fds)
        except Broken:
            self._broken = True  # the client's monitor thread reports the wire gone
            return frame
        if not sent:
            return frame
        frame.close_fds()
        return Frame(frame.data[sent:])

    def run(self) -> None:
        """The sender thread: write the waiting frames in order, waiting on the wire as long
        as it takes, until ``close`` or the wire breaks."""
        while True:
            with self._changed:
                while not self._waiting and not self._closing:
                    self._changed.wait()
                if self._closing:
                    return
                frame = self._waiting.popleft()
                self._busy = True
                self._changed.notify_all()
            try:
                self.wire.send_frame(frame.data, frame.fds)
            except Broken:
                with self._changed:
                    self._broken = True
                return
            finally:
                frame.close_fds()
                with self._changed:
                    self._busy = False

    def close(self) -> None:
        """Stop the sender thread (what waits stays, for ``drop``)."""
        with self._changed:
            self._closing = True
            self._changed.notify_all()

    def drop(self) -> None:
        """Forget every frame still waiting, closing its descriptors."""
        with self._changed:
            while self._waiting:
                self._waiting.popleft().close_fds()
            self._changed.notify_all()
