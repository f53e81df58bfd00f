"""The event outbox: events queue during a tick and go out after its status, never blocking."""

from __future__ import annotations

import select

from control.rt.events import ControllerEvent
from control.rt.wire import Broken, Wire

OUTBOX_LIMIT = 256


class Outbox:
    """A frozen client stops reading and the loop must go on: events wait while the channel is
    full, and the oldest are dropped past ``OUTBOX_LIMIT``."""

    def __init__(self, wire: Wire) -> None:
        self.wire = wire
        self.open = True
        self.queue: list[ControllerEvent] = []
        self.writable = select.poll()  # a unix socket polls writable with 3/4 of its buffer free
        self.writable.register(wire.fileno(), select.POLLOUT)

    def put(self, event: ControllerEvent) -> None:
        self.queue.append(event)

    def flush(self) -> None:
        """Send what the channel takes now; a broken channel closes the outbox."""
        queue = self.queue
        if not self.open:
            queue.clear()
            return
        while queue and self.writable.poll(0):
            try:
                self.wire.send(queue.pop(0))
            except Broken:
                self.open = False
                queue.clear()
                return
        del queue[:-OUTBOX_LIMIT]
