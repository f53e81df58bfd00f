"""The command channel, the rtf FIFO's analogue: typed commands in, checked before use."""

from __future__ import annotations

import select
from multiprocessing.connection import Connection

from control.commands import Command
from control.events import Notice, Refused
from control.heartbeat import ClientWatch
from control.outbox import Outbox

COMMANDS_PER_TICK = 16


class CommandChannel:
    """Inputs: the client's socket. Outputs: up to ``COMMANDS_PER_TICK`` records a tick.

    Never blocks. Every message counts as a heartbeat; one that cannot be read
    is refused here, a closed socket ends the client for good.
    """

    def __init__(self, conn: Connection, outbox: Outbox, client: ClientWatch) -> None:
        self.conn = conn
        self.outbox = outbox
        self.client = client
        self.poller = select.poll()
        self.poller.register(conn.fileno(), select.POLLIN)
        self.received: list[object] = []

    def receive(self) -> list[object]:
        """What arrived since the last tick (a list reused from tick to tick)."""
        received = self.received
        received.clear()
        if not self.outbox.open:
            return received
        for _ in range(COMMANDS_PER_TICK):
            if not self.poller.poll(0):  # one syscall; Connection.poll builds a selector
                break
            try:
                received.append(self.conn.recv())
            except (EOFError, OSError):
                self.outbox.open = False
                self.client.gone()
                break
            except Exception as exc:  # a message that does not unpickle is no command
                self.outbox.put(Refused("message", f"unreadable: {type(exc).__name__}: {exc}"))
            if self.client.heard():
                self.outbox.put(Notice("client is back; holding position"))
        return received


def command_name(record: object) -> str:
    """What to call a record in a refusal."""
    return record.NAME if isinstance(record, Command) else type(record).__name__
