"""How a client reaches its controller: a ``Link``.

A ``ControlClient`` is made of a link, the command API and a run keeper. The link is
what differs between a client that started its own controller (``EmbeddedLink``,
``control/embedded.py``) and one attached to a controller service (``ServiceLink``,
``control/attached.py``): the wire its commands go out on and its events come in on, the
control segment it maps, what it was told at the start, whether it may command, how its
heartbeat reaches the controller, and what closing it means. Commands go out in order,
from the caller's thread when the wire takes them at once, else from the link's own sender
thread, so no caller ever waits on the wire (``control/outgoing.py``).
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.shared_memory import SharedMemory
from pathlib import Path

from control.outgoing import Outgoing
from control.rt.commands import Command
from control.rt.layout import ControlLayout
from control.rt.seqlock import SeqlockReader, SeqlockWriter
from control.rt.wire import Message, Wire
from control.timing import Timing
from hw.machine import Coefficients, Machine

OUTGOING = 64  # commands waiting for the wire; more means the other end is not reading
ANSWER_S = 2.0  # how long take_command and release_command wait for the service's answer


class ControllerError(RuntimeError):
    """The control subprocess could not start, crashed or died."""


class NotCommanding(ControllerError):
    """This client observes: another holds command, or nobody does and it has not taken it."""


@dataclass(frozen=True)
class Setting:
    """What a client works with, whoever runs the controller: the machine, its backend, the
    timing and sample time, where runs go, and how the controller was scheduled."""

    machine: Machine
    backend: str
    port: str | None
    timing: Timing
    dt: float  # between path rows, s
    data_dir: Path
    lockstep: bool = False
    notice: str = ""
    realtime: bool = False
    first_move_id: int = 1  # a service's clients number their moves apart
    name: str = ""  # the name the service gave this client ("" for one's own controller)
    service_pid: int = 0  # the service's process (0: none)


class Link(ABC):
    """The wire to the controller (or the service in front of it) and the control segment.

    ``restart`` says what to do after the controller is lost; ``closed`` why the wire
    ended. A subclass says who runs the controller."""

    restart = ""
    closed = ""

    def __init__(self, wire: Wire, segment: SharedMemory, setting: Setting) -> None:
        self.wire = wire
        self.segment = segment
        self.setting = setting
        self.layout = ControlLayout(setting.machine.n_joints)
        self.outgoing = Outgoing(wire, OUTGOING)
        self._sender = threading.Thread(target=self.outgoing.run, name="servodesk-commands",
                                        daemon=True)

    def start(self) -> None:
        self._sender.start()

    def put(self, message: Message) -> None:
        """Send ``message`` now, or queue it behind the others, never waiting on the wire;
        ``queue.Full`` when the last ``OUTGOING`` are still waiting (the other end frozen or
        flooded)."""
        self.outgoing.put_nowait(message)

    def write_coefficients(self, which: str, coefficients: Coefficients) -> None:
        """Write a packed set where the controller reads it on ``SetCoefficients``. The writer
        takes the seqlock's count as it is now: under a controller service another client may
        have written the set since this one attached."""
        writer = SeqlockWriter(self.segment.buf, self.layout.coefficient_offset(which),
                               self.layout.coefficients.struct)
        try:
            writer.write(*self.layout.coefficients.encode(coefficients))
        finally:
            writer.release()

    def read_coefficients(self, which: str) -> tuple:
        """The packed set the controller has now (``CoefficientLayout``'s values)."""
        reader = SeqlockReader(self.segment.buf, self.layout.coefficient_offset(which),
                               self.layout.coefficients.struct)
        try:
            return reader.read()
        finally:
            reader.release()

    def close(self) -> None:
        """Stop sending (what is queued stays, for ``release`` to drop)."""
        self.outgoing.close()
        if self._sender.is_alive():
            self._sender.join(timeout=0.2)

    def release(self) -> None:
        """After the client's last use: close the wire, drop what was never sent (closing its
        descriptors); a subclass then lets go of the segment and the process."""
        self.wire.close()
        self.outgoing.drop()

    # -- what a subclass says ---------------------------------------------------------------

    @property
    @abstractmethod
    def pid(self) -> int:
        """The control process's id."""

    @abstractmethod
    def exited(self) -> str:
        """Why the controller is gone, or "" while it runs."""

    @abstractmethod
    def beat(self, words: memoryview) -> None:
        """One heartbeat of this client (``words``: its words in the control segment)."""

    @abstractmethod
    def may_send(self, command: Command) -> None:
        """Raise ``NotCommanding`` with the reason if this client may not send ``command``."""

    @abstractmethod
    def observe(self, record: object) -> None:
        """See an event on its way to the client (who holds command, say)."""

    @abstractmethod
    def stop(self, moves_done: Callable[[float], None]) -> None:
        """Let go of the controller: stop it, or give command back (``moves_done(s)`` waits
        at most ``s`` for the client's moves to end)."""

    @abstractmethod
    def log(self) -> str:
        """What the control process wrote to its stderr, if this link can see it."""

    @property
    @abstractmethod
    def commanding(self) -> bool:
        """Whether this client's commands are carried out."""

    @property
    @abstractmethod
    def role(self) -> str:
        """In a sentence: whether this client commands, and who does if not ("" when it runs
        its own controller: there is nobody else)."""

    @property
    @abstractmethod
    def holder(self) -> str:
        """Who holds command ("" nobody, or nobody else)."""

    @abstractmethod
    def take_command(self, timeout_s: float) -> None:
        """Become the commanding client."""

    @abstractmethod
    def release_command(self, timeout_s: float) -> None:
        """Give command back: the controller holds every joint."""
