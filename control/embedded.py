"""A client's own controller: ``EmbeddedLink`` starts the control subprocess and owns it.

It saves the runs a dead process left (``control/recovery.py``) and clears orphans
first, makes the control segment (the machine's coefficient sets written in), starts the
control process (a fork of a preloaded server, ``control/launcher.py``) on one end of a
socketpair and waits for it to say it is ready. It always commands; its heartbeat is a word
in shared memory the controller reads every tick, so a full or frozen channel never delays it.
Closing stops the controller
(valves closed), kills it if it does not stop, and unlinks the segment.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from multiprocessing.shared_memory import SharedMemory
from pathlib import Path
from typing import IO

import control
from control.launcher import ControllerProcess, launch
from control.link import ControllerError, Link, Setting
from control.off_core import come_back, controller_core, keep_off
from control.recovery import recover_runs
from control.rt import shm
from control.rt.channel import client_end
from control.rt.commands import Command, Shutdown
from control.rt.events import ControllerEvent, Crash, Ready
from control.rt.layout import HEARTBEAT_WORD, ControlLayout
from control.rt.process_config import ProcessConfig
from control.rt.wire import Broken, Message, Unreadable, Wire
from hw.machine import Coefficients

CLOSE_WAIT_S = 1.0  # how long the controller may take to stop before it is killed
_SESSIONS = itertools.count(1)  # several clients in one process get their own segments


class EmbeddedLink(Link):
    """The link of a client that started its controller: it commands, and stops it on close."""

    restart = "restart servodesk to continue"
    closed = "the control process closed its channel"

    @classmethod
    def launch(cls, setting: Setting, coefficients: Sequence[Coefficients], *, seed: int,
              realtime: bool, spin_us: float, heartbeat_timeout_s: float,
              orphan_timeout_s: float, start_timeout_s: float, sim_options: dict,
              early: Callable[[ControllerEvent], None]) -> tuple[EmbeddedLink, list[str]]:
        """Start the control process for ``setting`` with the hold and track sets in
        ``coefficients``; the link, and what the clean-up before it found (notices).
        ``early`` gets the events the controller sends before it is ready."""
        machine, timing = setting.machine, setting.timing
        notices = recover_runs(setting.data_dir) + shm.cleanup_orphans()[1]
        layout = ControlLayout(machine.n_joints)
        segment = shm.create(f"ctl{next(_SESSIONS)}", layout.size, "the controller's status")
        layout.write_header(segment.buf)
        slots = timing.slots(machine)
        config = ProcessConfig(
            machine=str(machine.path), backend=setting.backend, port=setting.port, seed=seed,
            lockstep=setting.lockstep, control_segment=segment.name,
            period_s=setting.dt / slots, spin_us=spin_us, realtime=realtime,
            heartbeat_timeout_s=heartbeat_timeout_s, orphan_timeout_s=orphan_timeout_s,
            sim_options={**timing.sim_options(machine), **sim_options}, slots=slots,
            slips=timing.slips)
        ours, theirs = socket.socketpair()
        stderr = tempfile.TemporaryFile()  # noqa: SIM115  # lives as long as the link
        try:
            proc = launch(config.to_json(), theirs.fileno(), stderr.fileno(), _child_env(),
                          start_timeout_s)
        except BaseException:
            stderr.close()
            ours.close()
            shm.release(segment, unlink=True)
            raise
        finally:
            theirs.close()
        link = cls(client_end(ours), segment, setting, proc, stderr)
        for which, c in zip(("hold", "track"), coefficients, strict=True):
            link.write_coefficients(which, c)
        try:
            link.setting = link._await_ready(start_timeout_s, early)
        except BaseException:
            link.close()
            link.release()
            raise
        core = controller_core(proc.pid) if link.setting.realtime else None
        if core is not None and keep_off(core):  # control/off_core.py: why
            link.kept_off = core
        return link, notices

    def __init__(self, wire: Wire, segment: SharedMemory, setting: Setting,
                 proc: ControllerProcess, stderr: IO[bytes]) -> None:
        super().__init__(wire, segment, setting)
        self.process = proc
        self._stderr = stderr
        self.kept_off: int | None = None  # the controller's core, this process's threads off it

    def _await_ready(self, timeout_s: float, early: Callable[[ControllerEvent], None]
                     ) -> Setting:
        """Wait for ``Ready``; the setting with how the controller was scheduled."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.wire.poll(0.01):
                try:
                    record = self.wire.recv().record
                except Unreadable:
                    continue
                except Broken:
                    break
                if isinstance(record, Ready):
                    # the controller watches the heartbeat from now: beat before the client's
                    # threads start, which a busy UI (building its screen) can delay
                    words = self.layout.client_words(self.segment.buf)
                    self.beat(words)
                    words.release()
                    return Setting(**{**vars(self.setting), "notice": record.notice,
                                      "realtime": record.realtime})
                if isinstance(record, Crash):
                    raise ControllerError(f"control process failed to start: {record.message}")
                early(record)
            elif self.process.poll() is not None:
                break
        code = self.process.poll()
        raise ControllerError("control process did not start"
                              + (f" (exit code {code}): {self._last_words()}" if code is not None
                                 else f" within {timeout_s:g} s"))

    def _last_words(self) -> str:
        """The last line the controller wrote to stderr (its traceback's summary)."""
        lines = self.log().strip().splitlines()
        return lines[-1] if lines else "no output"

    @property
    def pid(self) -> int:
        return self.process.pid

    def exited(self) -> str:
        code = self.process.poll()
        return "" if code is None else f"the control process exited (code {code})"

    def beat(self, words: memoryview) -> None:
        """The heartbeat word in shared memory (no channel to fill, so a frozen controller
        never blocks it). A controller service calls it for the client that commands."""
        words[HEARTBEAT_WORD] = time.monotonic_ns()

    def may_send(self, command: Command) -> None:
        """The client that started its controller may send anything."""

    def observe(self, record: object) -> None:
        """Nothing to follow: nobody else commands."""

    def stop(self, moves_done: Callable[[float], None]) -> None:
        """Ask the controller to stop and give it ``CLOSE_WAIT_S`` to do so."""
        with contextlib.suppress(Exception):
            self.put(Message(Shutdown()))
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(timeout=CLOSE_WAIT_S)

    def close(self) -> None:
        """Stop sending; terminate (then kill) a controller that is still there."""
        super().close()
        for stop in (self.process.terminate, self.process.kill):
            if self.process.poll() is not None:
                break
            stop()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.process.wait(timeout=0.3)

    def release(self) -> None:
        super().release()
        shm.release(self.segment, unlink=True)
        self._stderr.close()
        self.process.close()
        if self.kept_off is not None:
            come_back(self.kept_off)
            self.kept_off = None

    def log(self) -> str:
        with contextlib.suppress(OSError, ValueError):
            self._stderr.seek(0)
            return self._stderr.read().decode("utf-8", "replace")
        return ""

    @property
    def commanding(self) -> bool:
        return True

    @property
    def role(self) -> str:
        return ""

    @property
    def holder(self) -> str:
        return ""

    def take_command(self, timeout_s: float) -> None:
        """Already: a client that started its controller always commands it."""

    def release_command(self, timeout_s: float) -> None:
        raise ControllerError("this client started its controller: it always commands it; "
                              "close it to stop the controller")


def _child_env() -> dict[str, str]:
    """The environment for the control process, with servodesk importable from where it is."""
    root = str(Path(control.__file__).resolve().parent.parent)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return env
