"""The controller service's trust boundaries, tried on real processes as an attacker and a
careless user would (issue 22): only the commander moves the robot, its liveness is judged
on the path its commands take, and the service outlives what its clients do to it."""

from __future__ import annotations

import json
import os
import pickle
import resource
import signal
import socket
import stat
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from control import rendezvous
from control.client import ControlClient, ControllerError
from control.motion import moves
from control.rt import shm
from control.rt.layout import Mode
from hw.machine import load_machine
from tests.conftest import ROOT, ServiceProcess
from tests.control.doomed_client import DOOMED

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


def until(condition: Callable[[], object], timeout: float = 10.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what or condition}")
        time.sleep(0.005)


@pytest.fixture
def service(tmp_path: Path):
    """A service with the controller's own heartbeat timeout (250 ms), as an operator runs it."""
    started = ServiceProcess(tmp_path)
    yield started
    started.kill()


def test_a_frozen_service_holds_the_joint_its_commander_jogs(service) -> None:
    """The commander jogs Rotate at 30 %; the service freezes (SIGSTOP): the commander's
    heartbeats travel through it, so they stop reaching the controller, which holds (before:
    the commander wrote its heartbeat into shared memory itself, and Rotate ran on 27.9°)."""
    commander = ControlClient.attach(service.socket, name="jogger")
    try:
        commander.take_command()
        commander.jog_joint(ROTATE, 30.0)
        until(lambda: commander.status().mode == Mode.MANUAL_ACTUATE, what="the jog")
        until(lambda: abs(commander.status().valve[ROTATE]) > 0, what="the valve to open")
        stopped_ns = time.monotonic_ns()
        os.kill(service.proc.pid, signal.SIGSTOP)
        try:
            until(lambda: commander.status().mode == Mode.HOLD, timeout=10,
                  what="the controller to hold")
            held = commander.status()
            print(f"held {(held.wall_ns - stopped_ns) / 1e6:.0f} ms after the service froze")
            assert held.wall_ns - stopped_ns < 2e9
            assert held.duty[ROTATE] == 0.0 or held.mode == Mode.HOLD
        finally:
            os.kill(service.proc.pid, signal.SIGCONT)
    finally:
        commander.close()


PICKLE_BOMB = """
import os
class Boom:
    def __reduce__(self):
        return (os.system, ("touch {marker}",))
"""


def test_a_pickle_on_the_socket_runs_no_code(service, tmp_path: Path) -> None:
    """A pickle payload, framed as the old protocol framed its messages, after a proper
    handshake: the service reads it as a message that is no record, and nothing runs."""
    marker = tmp_path / "pwned"
    namespace: dict = {}
    exec(PICKLE_BOMB.format(marker=marker), namespace)  # the attacker's class
    payload = pickle.dumps(namespace["Boom"]())
    wire = rendezvous.connect(service.socket)
    try:
        wire.send(rendezvous.Join("attacker", os.getpid()))
        assert isinstance(wire.recv().record, rendezvous.Hello)
        wire.send_bytes(payload)
        until(lambda: wire.poll(0.1), what="the service's answer")
        answer = wire.recv().record
        while getattr(answer, "command", "") != "message":
            answer = wire.recv().record
        assert "unreadable" in answer.reason
    finally:
        wire.close()
    time.sleep(0.5)  # a code run would have touched the file by now; nothing to wait for
    assert not marker.exists()
    assert service.proc.poll() is None
    ControlClient.attach(service.socket, name="after").close()


def test_a_running_move_cannot_be_rewritten_in_shared_memory(service) -> None:
    """An observer (here, the test, as the same user) rewrites the commander's move segment
    while its step to 5° runs, with 60° rows where the path was (before: Rotate went to 60°).
    The path is sealed in a memory file the controller maps read-only: the step ends at 5°,
    and writing the sealed file itself is refused by the kernel."""
    commander = ControlClient.attach(service.socket, name="commander")
    try:
        commander.take_command()
        start = np.array(commander.status().position)
        path = moves.step(start, ROTATE, start[ROTATE] + 5.0, duration=3.0,
                          machine=UNIMATE, dt=commander.dt)
        handle = commander.move(path, kind="step")
        until(lambda: commander.status().move_done > 50, what="the move to run")
        rewritten = 0
        for name in shm.leftover_segments():
            if shm.owner_pid(name) != os.getpid() or not shm.is_move_segment(name):
                continue
            segment = shm.attach(name)
            try:  # where the path was (docs/shared_memory.md, layout 3), 60° rows
                samples, meta_size = (struct.unpack_from("<Q", segment.buf, offset)[0]
                                      for offset in (8, 32))
                offset = (64 + 256 + meta_size + 7) // 8 * 8
                rows = np.ndarray((samples, 6), np.float64, segment.buf, offset)
                rows[:] = [*start[:ROTATE], 60.0, *start[ROTATE + 1:]]
                rewritten += 1
            finally:
                del rows
                shm.release(segment, unlink=False)
        assert rewritten >= 1
        for fd in Path(f"/proc/{commander.pid}/fd").iterdir():
            if "memfd:servodesk-path" in os.readlink(fd):
                with pytest.raises(PermissionError), open(fd, "r+b") as file:
                    file.write(struct.pack("<d", 60.0))
        result = commander.wait(handle, timeout=60)
        assert abs(commander.status().desired[ROTATE] - (start[ROTATE] + 5.0)) < 1e-6, \
            result.status
        assert abs(commander.status().position[ROTATE] - 60.0) > 30.0
    finally:
        commander.close()


def test_attach_to_a_frozen_service_honours_its_timeout(service) -> None:
    """Before: attach() waited for the key handshake for ever (servodesk --attach and serve's
    probe too)."""
    os.kill(service.proc.pid, signal.SIGSTOP)
    outcome: list[object] = []
    try:
        started = time.monotonic()
        worker = threading.Thread(target=lambda: outcome.append(_attach(service.socket, 1.0)),
                                  daemon=True)
        worker.start()
        worker.join(30.0)
        assert not worker.is_alive(), "attach() still waiting 30 s later"
        assert isinstance(outcome[0], ControllerError), outcome
        assert "within 1 s" in str(outcome[0])
        print(f"attach gave up after {time.monotonic() - started:.2f} s")
    finally:
        os.kill(service.proc.pid, signal.SIGCONT)
    _attached_and_closed(service.socket)


def _attach(path: Path, timeout_s: float) -> object:
    try:
        return ControlClient.attach(path, name="patient", timeout_s=timeout_s)
    except Exception as exc:
        return exc


def test_a_connect_flood_and_silent_connections_leave_the_service_serving(service) -> None:
    """A flood of connections that never authenticate, with the service short of file
    descriptors (its limit cut to 64): it logs running out, drops each silent connection
    after the handshake time, and serves again once the flood ends (before: its accept thread
    died for good, silently)."""
    soft, hard = resource.prlimit(service.proc.pid, resource.RLIMIT_NOFILE)
    resource.prlimit(service.proc.pid, resource.RLIMIT_NOFILE, (64, hard))
    flood: list[socket.socket] = []
    try:
        for _ in range(300):
            sock = socket.socket(socket.AF_UNIX)
            sock.setblocking(False)
            try:
                sock.connect(str(service.socket))
            except (BlockingIOError, ConnectionRefusedError, OSError):
                sock.close()
                continue
            flood.append(sock)
        until(lambda: "cannot accept a client" in service.log.read_text()
              or "refused a connection" in service.log.read_text(), timeout=30,
              what="the service to say it is out of room")
        silent = flood[0]
        silent.setblocking(True)
        silent.settimeout(30)
        data = b""
        while chunk := silent.recv(4096):  # the challenge, then the end: dropped
            data += chunk
        assert b"Challenge" in data
    finally:
        for sock in flood:
            sock.close()
    resource.prlimit(service.proc.pid, resource.RLIMIT_NOFILE, (soft, hard))
    until(lambda: not isinstance(_attached_and_closed(service.socket), Exception), timeout=60,
          what="an attach to work again")
    assert service.proc.poll() is None


def _attached_and_closed(path: Path) -> object:
    outcome = _attach(path, 5.0)
    if isinstance(outcome, ControlClient):
        outcome.close()
    return outcome


def test_two_services_in_one_directory_keep_their_own_keys(tmp_path: Path) -> None:
    """Before: the second overwrote controller.key (attaching to the first then failed) and
    deleted it when it stopped."""
    shared = Path(tempfile_dir())
    first = ServiceProcess(tmp_path, socket=shared / "a.sock")
    second = ServiceProcess(tmp_path, socket=shared / "b.sock")
    try:
        ControlClient.attach(first.socket, name="one").close()
        ControlClient.attach(second.socket, name="two").close()
        assert second.stop() == 0
        ControlClient.attach(first.socket, name="still").close()
    finally:
        first.kill()
        second.kill()


def test_a_socket_in_a_shared_directory_leaves_its_mode_alone(tmp_path: Path) -> None:
    """A --socket in a sticky, world-writable directory such as /tmp: the service neither
    chmods the directory to 0700 (before: the sticky bit was lost for good) nor refuses it."""
    shared = Path(tempfile_dir())
    shared.chmod(0o1777)
    service = ServiceProcess(tmp_path, socket=shared / "robot.sock")
    try:
        ControlClient.attach(service.socket, name="user").close()
        assert stat.S_IMODE(shared.stat().st_mode) == 0o1777
        assert stat.S_IMODE(service.socket.stat().st_mode) == 0o600
        assert stat.S_IMODE(rendezvous.key_path(service.socket).stat().st_mode) == 0o600
    finally:
        service.kill()
    assert stat.S_IMODE(shared.stat().st_mode) == 0o1777


def tempfile_dir() -> str:
    import tempfile

    return tempfile.mkdtemp(prefix="sd-")  # short: a socket's path has at most 107 bytes


def test_a_killed_commanders_run_is_saved_as_such(service) -> None:
    """Before: the run of a commander killed mid-move was saved as "aborted by operator"."""
    watcher = ControlClient.attach(service.socket, name="watcher")
    doomed = subprocess.Popen([sys.executable, "-c", DOOMED, str(service.socket)], cwd=ROOT,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert doomed.stdout is not None
        name = doomed.stdout.readline().strip()
        until(lambda: watcher.status().mode == Mode.FOLLOW_TRACK, what="the doomed move")
        os.kill(doomed.pid, signal.SIGKILL)
        doomed.wait(timeout=30)
        until(lambda: list(service.data_dir.glob("*.json")), timeout=30, what="the run")
        run = json.loads(next(service.data_dir.glob("*.json")).read_text())
        assert run["status"] == f"interrupted: the commanding client ({name}) left", run["status"]
    finally:
        if doomed.poll() is None:
            doomed.kill()
        watcher.close()
