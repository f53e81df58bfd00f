"""A client of a controller that ``servodesk controller`` runs: ``ServiceLink``, the link
``ControlClient.attach`` gives a client.

It connects to the service's socket (both sides proving the key, ``control/rendezvous.py``),
joins, and attaches the control segment the hello names (status, scope, latency, the
coefficient sets); the client makes its moves' segments itself and saves their runs as a
client of its own controller does. It observes until ``take_command``: only the commander's
commands are relayed, and only its heartbeats (sent to the service every 50 ms, like every
client's) reach the controller; any client's E-stop is (its E-stop count in shared memory
too). Closing detaches: command is released (the controller holds), the controller runs on.
"""

from __future__ import annotations

import contextlib
import os
import queue
import sys
import time
from collections.abc import Callable
from multiprocessing.shared_memory import SharedMemory
from pathlib import Path

from control import rendezvous
from control.link import ANSWER_S, ControllerError, Link, NotCommanding, Setting
from control.rt import shm
from control.rt.commands import Command, EmergencyStop
from control.rt.events import Commander, Refused
from control.rt.wire import Broken, Message, Wire
from control.timing import Timing
from hw.machine import load_machine

CLOSE_WAIT_S = 1.0  # detaching: how long the client's moves may take to end
TAKE, RELEASE = "take command", "release command"


class ServiceLink(Link):
    """The link of a client attached to a controller service: it observes until it takes
    command, and leaves the controller running when it closes."""

    restart = "start `servodesk controller` again, then attach"
    closed = "the controller service closed its connection (stopped or killed)"

    @classmethod
    def connect(cls, path: str | Path | None, name: str, timeout_s: float) -> ServiceLink:
        """Attach to the service at ``path`` (default: the user's), all within ``timeout_s``."""
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
            segment = shm.attach(hello.control_segment)
        except (TimeoutError, Broken) as exc:
            wire.close()
            raise ControllerError(f"the controller service did not answer within "
                                  f"{timeout_s:g} s ({exc})") from None
        except BaseException:
            wire.close()
            raise
        setting = Setting(
            machine=load_machine(hello.machine), backend=hello.backend, port=hello.port,
            timing=Timing(hello.timing, hello.interrupt_ms, tuple(hello.slips)), dt=hello.dt,
            data_dir=Path(hello.data_dir), notice=hello.notice, realtime=hello.realtime,
            first_move_id=hello.id_base, name=hello.client, service_pid=hello.service_pid)
        return cls(wire, segment, setting, hello)

    def __init__(self, wire: Wire, segment: SharedMemory, setting: Setting,
                 hello: rendezvous.Hello) -> None:
        super().__init__(wire, segment, setting)
        self.name = hello.client
        self._holder = hello.holder
        self._controller_pid = hello.controller_pid
        self._answers: queue.Queue[Commander | Refused] = queue.Queue()

    # -- command: taken and released explicitly ------------------------------------------------

    @property
    def holder(self) -> str:
        return self._holder

    @property
    def commanding(self) -> bool:
        return bool(self._holder) and self._holder == self.name

    @property
    def role(self) -> str:
        if self.commanding:
            return "commanding"
        return (f"observing: command is held by {self._holder}" if self._holder
                else "observing: nobody holds command")

    def take_command(self, timeout_s: float = ANSWER_S) -> None:
        """``NotCommanding`` with the reason if another holds command."""
        self._ask(rendezvous.TakeCommand(), TAKE, lambda: self.commanding, timeout_s)

    def release_command(self, timeout_s: float = ANSWER_S) -> None:
        self._ask(rendezvous.ReleaseCommand(), RELEASE, lambda: not self.commanding, timeout_s)

    def _ask(self, request: object, what: str, granted: Callable[[], bool],
             timeout_s: float) -> None:
        """Send ``request`` and wait until ``granted()`` or the service refuses ``what``."""
        answers = self._answers
        while not answers.empty():  # answers to earlier requests
            answers.get_nowait()
        self.outgoing.put(Message(request))
        deadline = time.monotonic() + timeout_s
        while not granted():
            try:
                answer = answers.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise ControllerError(f"{what}: no answer from the controller service within "
                                      f"{timeout_s:g} s") from None
            if isinstance(answer, Refused) and answer.command == what:
                raise NotCommanding(f"{what} refused: {answer.reason}")

    def observe(self, record: object) -> None:
        if isinstance(record, Commander):
            self._holder = record.holder
            self._answers.put(record)
        elif isinstance(record, Refused) and record.command in (TAKE, RELEASE):
            self._answers.put(record)

    def may_send(self, command: Command) -> None:
        if not self.commanding and not isinstance(command, EmergencyStop):
            raise NotCommanding(f"{self.role}; take it first")

    def beat(self, words: memoryview) -> None:
        """A heartbeat to the service (which relays the commander's to the controller): along
        the commands' path, so a frozen service stops it too. Dropped while the outgoing queue
        is full: the commands in it will say the client is alive."""
        with contextlib.suppress(queue.Full):
            self.put(Message(rendezvous.Heartbeat()))

    # -- the controller is the service's -------------------------------------------------------

    @property
    def pid(self) -> int:
        return self._controller_pid

    def exited(self) -> str:
        return "" if shm.pid_alive(self._controller_pid) else "the control process is gone"

    def stop(self, moves_done: Callable[[float], None]) -> None:
        """Detach: release command (the controller holds, which ends this client's moves),
        and wait ``CLOSE_WAIT_S`` for them to end; the service saves any later."""
        if self.commanding:
            self.outgoing.put(Message(rendezvous.ReleaseCommand()))
        moves_done(CLOSE_WAIT_S)

    def release(self) -> None:
        """The segment is the service's: let go of it, unlinked by nobody here."""
        super().release()
        shm.release(self.segment, unlink=False)

    def log(self) -> str:
        return ""  # the controller logs to the stderr of `servodesk controller`
