"""The command channel, the rtf FIFO's analogue: typed commands in, checked, dispatched."""

from __future__ import annotations

import socket
from collections.abc import Callable, Mapping

from control.rt.commands import COMMANDS, Command, StartMove
from control.rt.events import EVENTS, MoveDone, Refused
from control.rt.heartbeat import ClientWatch
from control.rt.outbox import Outbox
from control.rt.wire import Broken, Codec, Message, Unreadable, Wire

COMMANDS_PER_TICK = 16
CODEC = Codec(COMMANDS + EVENTS)  # client and control process: commands in, events out
COMMAND_LIMIT = 64 * 1024  # bytes of one command: a few numbers and names
EVENT_LIMIT = 1 << 20  # bytes of one event: a move's timeline of 600 s at most
FRAME_S = 1.0  # the client writes a frame at once: one begun and not whole by then is a break


def client_end(sock: socket.socket) -> Wire:
    """The client's end of the channel: commands out, events in."""
    return Wire(sock, CODEC, EVENT_LIMIT)


def controller_end(sock: socket.socket) -> Wire:
    """The control process's end: commands in, events out."""
    return Wire(sock, CODEC, COMMAND_LIMIT, FRAME_S)


class CommandChannel:
    """Inputs: the client's socket. Outputs: each record read, checked and handed to the
    handler of its type; up to ``COMMANDS_PER_TICK`` a tick.

    Never blocks and never raises: every message counts as a heartbeat; one that
    is no record of ours, of no command type or fails its checks (``Command.check``) is
    refused with the reason, and moves and latches nothing; a closed or broken stream ends
    the client for good.
    """

    def __init__(self, wire: Wire, outbox: Outbox, client: ClientWatch, n_joints: int,
                 handlers: Mapping[type[Command], Callable[..., None]]) -> None:
        self.wire = wire
        self.outbox = outbox
        self.client = client
        self.n_joints = n_joints
        self.handlers = handlers

    def poll(self) -> None:
        """Carry out what arrived since the last tick."""
        if not self.outbox.open:
            return
        for _ in range(COMMANDS_PER_TICK):
            if not self.wire.poll():  # one syscall
                return
            try:
                message = self.wire.recv()
            except Broken:
                self.outbox.open = False
                self.client.gone()
                return
            except Unreadable as exc:  # a whole message that is no command: refused
                self.outbox.put(Refused("message", f"unreadable: {exc}"))
                continue
            self.client.heard()
            self.deliver(message.record, message.fds)

    def deliver(self, record: object, fds: tuple[int, ...] = ()) -> None:
        """Check ``record`` and hand it to its handler (a move with the descriptor of its sealed
        path, ``fds``); refuse it with the reason if not. ``fds`` are closed either way."""
        try:
            handler = self.handlers.get(type(record))
            if handler is None:
                self.outbox.put(Refused(command_name(record),
                                        "not a command this controller knows"))
                return
            try:
                record.check(self.n_joints)
                if isinstance(record, StartMove):
                    handler(record, fds[0] if len(fds) == 1 else -1)
                else:
                    handler(record)
            except Exception as exc:  # a value that broke a handler: refused, never raised
                self.outbox.put(Refused(command_name(record), f"{type(exc).__name__}: {exc}"))
                if isinstance(record, StartMove):
                    self.outbox.put(MoveDone(record.move_id, f"refused: {exc}", 0))
        finally:
            Message(record, fds).close_fds()


def command_name(record: object) -> str:
    """What to call a record in a refusal."""
    return record.NAME if isinstance(record, Command) else type(record).__name__
