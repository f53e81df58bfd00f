"""Starting control processes: each one a fork of a preloaded server (``control/rt/forkserver.py``).

The first launch in a process starts the server (``python -m control.rt.forkserver``: the
control process's imports, done once); every launch forks a controller from it in a few
milliseconds, where a fresh interpreter spent 0.15–0.3 s of CPU importing them. A process that
starts many controllers (a test worker, a controller service's restarts, a benchmark) pays the
imports once. A server found dead is started again at the next launch; the controllers it
forked run on without it.

``ControllerProcess`` is what ``subprocess.Popen`` was to the client (``pid``, ``poll``,
``wait``, ``terminate``, ``kill``, ``returncode``): it waits on and signals the process through
its pidfd, so a pid reused after the controller's end is never signalled.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

from control.link import ControllerError

REPLY_LIMIT = 4096  # bytes of one answer of the server's: a pid, an exit code, a reason
EXIT_REPORT_S = 5.0  # how long an ended controller's exit code may take to be reported
LOST_CODE = 255  # the code of a controller whose server died before it could report it


class ForkServer:
    """The server process and this process's end of its socket."""

    def __init__(self, env: dict[str, str]) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.log_file = tempfile.TemporaryFile()  # noqa: SIM115  # lives as long as the server
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "control.rt.forkserver", str(theirs.fileno())],
                pass_fds=[theirs.fileno()], stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=self.log_file, env=env)
        except BaseException:
            ours.close()
            self.log_file.close()
            raise
        finally:
            theirs.close()
        self.sock = ours
        self.ended = False
        self.codes: dict[int, int] = {}  # exit codes reported, by pid (until it is reused)
        self.lock = threading.Lock()

    @property
    def alive(self) -> bool:
        return not self.ended and self.process.poll() is None

    def launch(self, request: bytes, fds: list[int], timeout_s: float) -> ControllerProcess:
        """Ask for one controller; its process once forked."""
        with self.lock:
            try:
                socket.send_fds(self.sock, [request], fds)
            except OSError as exc:
                if exc.errno == errno.EMSGSIZE:  # the server is fine: the request is too long
                    raise ControllerError(f"control process not started: its request of "
                                          f"{len(request)} bytes is more than the fork server's "
                                          "socket carries (a very large environment?)") from None
                self.ended = True
                raise ControllerError(f"the control processes' fork server has gone "
                                      f"({exc.strerror}): {self.last_words()}") from exc
            deadline = time.monotonic() + timeout_s
            while (answer := self._receive(deadline)) is not None:
                message, passed = answer
                if "pid" in message and len(passed) == 1:
                    self.codes.pop(int(message["pid"]), None)  # an earlier holder's of the pid
                    return ControllerProcess(self, int(message["pid"]), passed[0])
                for fd in passed:
                    os.close(fd)
                if "error" in message:
                    raise ControllerError(f"control process not started: {message['error']}")
        raise ControllerError("control process not started: its fork server "
                              + (f"ended: {self.last_words()}" if self.ended
                                 else f"did not answer within {timeout_s:g} s"))

    def exit_code(self, pid: int) -> int:
        """The code of ``pid``, which has ended, as the server reports it once it reaps it."""
        deadline = time.monotonic() + EXIT_REPORT_S
        with self.lock:
            while pid not in self.codes:
                answer = self._receive(deadline)
                if answer is None:
                    return LOST_CODE
                for fd in answer[1]:
                    os.close(fd)
            return self.codes[pid]

    def _receive(self, deadline: float) -> tuple[dict, list[int]] | None:
        """The next answer (an exit report noted in ``codes``), or None: the deadline passed
        or the server ended. Under ``self.lock``."""
        while not self.ended:
            ready, _, _ = select.select([self.sock], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                return None
            try:
                data, fds, _, _ = socket.recv_fds(self.sock, REPLY_LIMIT, 1)
            except OSError:
                data, fds = b"", []
            if not data:
                self.ended = True
                return None
            message = json.loads(data)
            if "exited" in message:
                self.codes[int(message["exited"])] = int(message["code"])
            return message, fds
        return None

    def last_words(self) -> str:
        with contextlib.suppress(OSError, ValueError):
            self.log_file.seek(0)
            lines = self.log_file.read().decode("utf-8", "replace").strip().splitlines()
            return lines[-1] if lines else "no output"
        return "no output"

    def log(self) -> str:
        """What the server wrote to stderr (``python -X importtime``'s lines, say)."""
        with contextlib.suppress(OSError, ValueError):
            self.log_file.seek(0)
            return self.log_file.read().decode("utf-8", "replace")
        return ""


class ControllerProcess:
    """One controller forked by the server: ``subprocess.Popen``'s part the client uses."""

    def __init__(self, server: ForkServer, pid: int, pidfd: int) -> None:
        self.server = server
        self.pid = pid
        self.pidfd = pidfd
        self.returncode: int | None = None

    def poll(self) -> int | None:
        return self.returncode if self.returncode is not None else self._ended(0.0)

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None and self._ended(timeout) is None:
            raise subprocess.TimeoutExpired(f"control process {self.pid}", timeout or 0.0)
        return self.returncode  # type: ignore[return-value]  # set by _ended

    def _ended(self, timeout: float | None) -> int | None:
        """The exit code once the process has ended within ``timeout`` (None: for ever)."""
        if self.pidfd < 0:
            return self.returncode
        ready, _, _ = select.select([self.pidfd], [], [], timeout)
        if ready:
            self.returncode = self.server.exit_code(self.pid)
        return self.returncode

    def send_signal(self, number: int) -> None:
        if self.returncode is None and self.pidfd >= 0:
            with contextlib.suppress(ProcessLookupError):
                signal.pidfd_send_signal(self.pidfd, number)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def close(self) -> None:
        """Let go of the pidfd (the process is neither waited for nor signalled after)."""
        if self.pidfd >= 0:
            os.close(self.pidfd)
            self.pidfd = -1


_server: ForkServer | None = None
_server_lock = threading.Lock()


def _forget_server() -> None:
    """In a fork of this process: the server's socket is the parent's, its answers too."""
    global _server
    _server = None


os.register_at_fork(after_in_child=_forget_server)


def launch(config: str, channel: int, stderr: int, env: dict[str, str],
           timeout_s: float) -> ControllerProcess:
    """Fork a controller with ``config`` (``ProcessConfig`` JSON), its end of the command
    channel and its stderr (descriptors), in ``env`` and this process's working directory."""
    global _server
    sys.audit("control.launch", config)  # a process start, as subprocess.Popen's event is
    with _server_lock:
        if _server is None or not _server.alive:
            _server = ForkServer(env)
        server = _server
    request = json.dumps({"config": config, "env": env, "cwd": os.getcwd()}).encode()
    return server.launch(request, [channel, stderr], timeout_s)


def server_log() -> str:
    """What this process's fork server wrote to stderr ("" if none was started)."""
    return _server.log() if _server is not None else ""
