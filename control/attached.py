"""A client of a controller that ``servodesk controller`` runs: ``ControlClient``'s API on
its socket (``ControlClient.attach``).

It attaches the service's control segment by name (status, scope, latency, the
coefficient sets), makes its moves' segments itself and saves their runs as the embedded
client does. It observes until ``take_command``: only the commander's commands are relayed,
and only its heartbeats (sent to the service every 50 ms, like every client's) reach the
controller; any client's E-stop is (its E-stop count in shared memory too). ``close``
detaches: command is released (the controller holds), the controller runs on.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import queue
import sys
import time
from collections.abc import Callable
from pathlib import Path

from control import rendezvous, shm
from control.client import CLOSE_WAIT_S, ControlClient, ControllerError, Event
from control.commands import Command, EmergencyStop
from control.events import Commander, Refused
from control.seqlock import SeqlockReader
from control.timing import Timing
from control.wire import Broken, Message
from hw.machine import Coefficients, load_machine

ANSWER_S = 2.0  # how long take_command and release_command wait for the service's answer
TAKE, RELEASE = "take command", "release command"


class NotCommanding(ControllerError):
    """This client observes: another holds command, or nobody does and it has not taken it."""


class AttachedClient(ControlClient):
    """``ControlClient`` on a controller service's socket: observes until ``take_command``."""

    OWNS_CONTROLLER = False
    RESTART = "start `servodesk controller` again, then attach"
    CHANNEL_CLOSED = "the controller service closed its connection (stopped or killed)"

    def __init__(self, path: str | Path | None = None, *, name: str = "",
                 on_event: Callable[[Event], None] | None = None,
                 timeout_s: float = 5.0) -> None:
        deadline = time.monotonic() + timeout_s
        try:
            wire = rendezvous.connect(path, timeout_s)
        except (TimeoutError, Broken, PermissionError) as exc:
            raise ControllerError(f"the controller service did not let this client in within "
                                  f"{timeout_s:g} s ({exc})") from None
        try:
            label = (name or Path(sys.argv[0]).name or "python")[:rendezvous.NAME_TEXT]
            wire.send(rendezvous.Join(label, os.getpid()))
            hello = rendezvous.receive(wire, rendezvous.Hello, deadline, "hello")
        except (TimeoutError, Broken) as exc:
            wire.close()
            raise ControllerError(f"the controller service did not answer within "
                                  f"{timeout_s:g} s ({exc})") from None
        except BaseException:
            wire.close()
            raise
        timing = Timing(hello.timing, hello.interrupt_ms, tuple(hello.slips))
        self._configure(load_machine(hello.machine), hello.backend, hello.data_dir, timing,
                        hello.dt, on_event)
        self.port = hello.port
        self.name = hello.client
        self.holder = hello.holder
        self.notice, self.realtime = hello.notice, hello.realtime
        self._controller_pid = hello.controller_pid
        self.service_pid = hello.service_pid
        self._ids = itertools.count(hello.id_base)
        self._answers: queue.Queue[Commander | Refused] = queue.Queue()
        self._wire = wire
        try:
            self._open_segment(shm.attach(hello.control_segment))
        except OSError:
            wire.close()
            raise
        self.coefficients = {which: self._coefficients_in_use(which) for which in self.coefficients}
        self._start_threads(())

    def _coefficients_in_use(self, which: str) -> Coefficients:
        """The set the controller has: the machine file's (by its name) or one a client set."""
        reader = SeqlockReader(self._segment.buf, self.layout.coefficient_offset(which),
                               self.layout.coefficients.struct)
        try:
            values = reader.read()
        finally:
            reader.release()
        given = self.coefficients[which]
        if values == self.layout.coefficients.encode(given):
            return given
        return self.layout.coefficients.decode(values, f"{which} (set by a client)")

    # -- command: taken and released explicitly ------------------------------------------------

    @property
    def commanding(self) -> bool:
        return bool(self.holder) and self.holder == self.name

    @property
    def role(self) -> str:
        """In a sentence: whether this client commands, and who does if not."""
        if self.commanding:
            return "commanding"
        return (f"observing: command is held by {self.holder}" if self.holder
                else "observing: nobody holds command")

    def take_command(self, timeout_s: float = ANSWER_S) -> None:
        """Become the commanding client; ``NotCommanding`` with the reason if another holds
        command."""
        self._ask(rendezvous.TakeCommand(), TAKE, lambda: self.commanding, timeout_s)

    def release_command(self, timeout_s: float = ANSWER_S) -> None:
        """Give command back: the controller holds every joint; another client may take it."""
        self._ask(rendezvous.ReleaseCommand(), RELEASE, lambda: not self.commanding, timeout_s)

    def _ask(self, request: object, what: str, granted: Callable[[], bool],
             timeout_s: float) -> None:
        """Send ``request`` and wait until ``granted()`` or the service refuses ``what``."""
        self.check()
        answers = self._answers
        while not answers.empty():  # answers to earlier requests
            answers.get_nowait()
        self._outgoing.put(Message(request))
        deadline = time.monotonic() + timeout_s
        while not granted():
            try:
                answer = answers.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise ControllerError(f"{what}: no answer from the controller service within "
                                      f"{timeout_s:g} s") from None
            if isinstance(answer, Refused) and answer.command == what:
                raise NotCommanding(f"{what} refused: {answer.reason}")

    def beat(self) -> None:
        """A heartbeat to the service (which relays the commander's to the controller): along
        the commands' path, so a frozen service stops it too. Dropped while the outgoing queue
        is full: the commands in it will say the client is alive."""
        with contextlib.suppress(queue.Full):
            self._outgoing.put_nowait(Message(rendezvous.Heartbeat()))

    def _may_send(self, command: Command) -> None:
        if not self.commanding and not isinstance(command, EmergencyStop):
            raise NotCommanding(f"{self.role}; take it first")

    def _dispatch(self, event: Event) -> None:
        record = event.record
        if isinstance(record, Commander):
            self.holder = record.holder
            self._answers.put(record)
        elif isinstance(record, Refused) and record.command in (TAKE, RELEASE):
            self._answers.put(record)
        super()._dispatch(event)

    # -- the controller is the service's -------------------------------------------------------

    @property
    def pid(self) -> int:
        return self._controller_pid

    @property
    def alive(self) -> bool:
        return not self.dead and shm.pid_alive(self._controller_pid)

    def _exited(self) -> str:
        return "" if shm.pid_alive(self._controller_pid) else "the control process is gone"

    def _stop_controller(self) -> None:
        """Detach: release command (the controller holds, which ends this client's moves),
        and save the runs that end within ``CLOSE_WAIT_S``; the service saves any later."""
        if self.commanding:
            self._outgoing.put(Message(rendezvous.ReleaseCommand()))
        deadline = time.monotonic() + CLOSE_WAIT_S
        for handle in list(self._moves.values()):
            handle.done.wait(max(deadline - time.monotonic(), 0.0))

    def _shutdown_process(self) -> None:
        """Not this client's process: it runs on."""

    def controller_log(self) -> str:
        return ""  # the controller logs to the stderr of `servodesk controller`
