"""The control processes' fork server: one interpreter that has imported the control process's
code once and forks a controller from it on each request (a zygote, as multiprocessing's
forkserver is, without its re-import of the client's ``__main__`` in every child).

A client process starts it once (``control/launcher.py``), as ``python -m
control.rt.forkserver FD`` on one end of a ``SOCK_SEQPACKET`` socketpair, and sends one
request a controller: a JSON object of the process's configuration, environment and working
directory, with two descriptors (the controller's end of its command channel, its stderr).
The server answers each with ``{"pid": N}`` and the child's pidfd (so that the client waits
for and signals that very process, never a reused pid), or ``{"error": "..."}``; and with
``{"exited": N, "code": C}`` once it has reaped it (``C`` as ``Popen.returncode``). It ends
when the client's end closes; its controllers run on (their client's watch stops them).

A controller started so does what ``python -m control.rt.process`` did in 0.15–0.3 s of
CPU (the imports) in a fork of a few milliseconds.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import sys
import traceback

from control.rt import process
from control.rt.channel import controller_end
from control.rt.process_config import ProcessConfig

REQUEST_LIMIT = 1 << 20  # bytes of one request: a configuration and an environment
REQUEST_KEYS = frozenset({"config", "env", "cwd"})
REASON_TEXT = 500  # characters of a refusal's reason: its answer fits the client's 4096 bytes


def serve(sock: socket.socket) -> None:
    """Fork a controller for each request until the client's end closes."""
    children: dict[int, int] = {}  # pidfd -> pid
    while True:
        ready, _, _ = select.select([sock, *children], [], [])
        for fd in ready:
            if fd in children:
                pid = children.pop(fd)
                os.close(fd)
                _, status = os.waitpid(pid, 0)
                reply(sock, {"exited": pid, "code": os.waitstatus_to_exitcode(status)})
                continue
            try:
                data, fds, _, _ = socket.recv_fds(sock, REQUEST_LIMIT, 2)
            except OSError:
                return
            if not data:
                return  # the client has gone
            started = start(data, fds, sock, children)
            for passed in fds:
                os.close(passed)
            if started is None:
                continue
            pid, pidfd = started
            children[pidfd] = pid
            reply(sock, {"pid": pid}, [pidfd])


def start(data: bytes, fds: list[int], sock: socket.socket,
          children: dict[int, int]) -> tuple[int, int] | None:
    """Fork the controller a request asks for: its pid and pidfd, or None (the client told)."""
    try:
        request = json.loads(data)
        if (not isinstance(request, dict) or set(request) != REQUEST_KEYS or len(fds) != 2
                or not isinstance(request["config"], str) or not isinstance(request["cwd"], str)
                or not isinstance(request["env"], dict)
                or not all(isinstance(k, str) and isinstance(v, str)
                           for k, v in request["env"].items())):
            raise ValueError("a request is {config, env, cwd} with two descriptors")
        config = ProcessConfig.from_json(request["config"])
    except (ValueError, TypeError) as exc:  # its text may quote the request: kept to a bound
        reply(sock, {"error": f"refused request: {str(exc)[:REASON_TEXT]}"})
        return None
    try:
        pid = os.fork()
    except OSError as exc:
        reply(sock, {"error": f"fork failed: {exc.strerror}"})
        return None
    if pid == 0:
        run_child(config, request, fds, [sock.fileno(), *children])
    return pid, os.pidfd_open(pid)


def run_child(config: ProcessConfig, request: dict, fds: list[int], server_fds: list[int]
              ) -> None:
    """In the fork: become the control process, as ``python -m control.rt.process`` would
    with that environment and working directory; never returns."""
    code = 1
    try:
        for fd in server_fds:
            os.close(fd)
        channel, stderr = fds
        os.dup2(stderr, 2)
        os.close(stderr)
        null = os.open(os.devnull, os.O_RDWR)
        os.dup2(null, 0)
        os.dup2(null, 1)
        os.close(null)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        process.main(config, controller_end(socket.socket(fileno=channel)))
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(code)


def reply(sock: socket.socket, message: dict, fds: list[int] | None = None) -> None:
    """One answer to the client; a client gone is the end of its controllers' watch, not ours."""
    with contextlib.suppress(OSError):
        socket.send_fds(sock, [json.dumps(message).encode()], fds or [])


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl+C belongs to the operator's UI
    serve(socket.socket(fileno=int(sys.argv[1])))
