"""The command channel, the rtf FIFO's analogue: typed commands in, checked, dispatched."""

from __future__ import annotations

import select
from collections.abc import Callable, Mapping
from multiprocessing.connection import Connection

from control.commands import Command, StartMove
from control.events import MoveDone, Refused
from control.heartbeat import ClientWatch
from control.outbox import Outbox

COMMANDS_PER_TICK = 16


class CommandChannel:
    """Inputs: the client's socket. Outputs: each record read, checked and handed to the
    handler of its type; up to ``COMMANDS_PER_TICK`` a tick.

    Never blocks and never raises: every message counts as a heartbeat; one that
    cannot be read, is of no known type or fails its checks (``Command.check``:
    unpickling bypasses the builders) is refused with the reason, and moves and
    latches nothing; a closed socket ends the client for good.
    """

    def __init__(self, conn: Connection, outbox: Outbox, client: ClientWatch, n_joints: int,
                 handlers: Mapping[type[Command], Callable[..., None]]) -> None:
        self.conn = conn
        self.outbox = outbox
        self.client = client
        self.n_joints = n_joints
        self.handlers = handlers
        self.poller = select.poll()
        self.poller.register(conn.fileno(), select.POLLIN)

    def poll(self) -> None:
        """Carry out what arrived since the last tick."""
        if not self.outbox.open:
            return
        for _ in range(COMMANDS_PER_TICK):
            if not self.poller.poll(0):  # one syscall; Connection.poll builds a selector
                return
            try:
                record = self.conn.recv()
            except (EOFError, OSError):
                self.outbox.open = False
                self.client.gone()
                return
            except Exception as exc:  # a message that does not unpickle is no command
                self.outbox.put(Refused("message", f"unreadable: {type(exc).__name__}: {exc}"))
                continue
            self.client.heard()
            self.deliver(record)

    def deliver(self, record: object) -> None:
        """Check ``record`` and hand it to its handler; refuse it with the reason if not."""
        handler = self.handlers.get(type(record))
        if handler is None:
            self.outbox.put(Refused(command_name(record), "not a command this controller knows"))
            return
        try:
            record.check(self.n_joints)
            handler(record)
        except Exception as exc:  # a record that bypassed its builder, or a value that broke
            self.outbox.put(Refused(command_name(record), f"{type(exc).__name__}: {exc}"))
            if isinstance(record, StartMove):
                self.outbox.put(MoveDone(record.move_id, f"refused: {exc}", 0))


def command_name(record: object) -> str:
    """What to call a record in a refusal."""
    return record.NAME if isinstance(record, Command) else type(record).__name__
