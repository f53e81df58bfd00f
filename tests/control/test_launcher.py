"""Controllers are forks of one preloaded server (control/launcher.py, control/rt/forkserver.py):
each its own process, in the environment of its launch, its end told as a subprocess's; a
dead server is started again and its controllers run on; a client's end is the server's."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from control import ControlClient, launcher
from control.embedded import _child_env
from control.link import ControllerError
from control.rt import shm
from tests.control.waiting import wait_until


def parent_of(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def client(tmp_path: Path, name: str) -> ControlClient:
    return ControlClient("rig", lockstep=True, data_dir=tmp_path / name, heartbeat_timeout_s=3.0)


def moves(client: ControlClient) -> bool:
    """The controller ticks: its tick count goes on."""
    first = client.status().tick
    wait_until(lambda: client.status().tick > first, 10, f"controller {client.pid} ticking")
    return True


def test_controllers_are_forks_of_one_server_in_the_environment_of_their_launch(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each controller reads the environment of its own launch, not the server's: with
    ``SERVODESK_WARM_UP=report`` a real-time controller writes its warm-up's counters as it
    ends, with ``0`` it runs none (control/rt/process.py reads it as the controller starts)."""
    logs: dict[str, list[str]] = {}
    shared = False
    for setting in ("0", "report", "0"):
        monkeypatch.setenv("SERVODESK_WARM_UP", setting)
        with ControlClient("rig", data_dir=tmp_path / setting, heartbeat_timeout_s=3.0) as each:
            server = launcher._server
            assert server is not None and parent_of(each.pid) == server.process.pid
            assert os.readlink(f"/proc/{each.pid}/cwd") == os.getcwd() and moves(each)
            shared |= setting == "report" and "shared" in each.notice  # no warm-up then
            os.kill(each.pid, signal.SIGTERM)  # its loop ends and the counters are written
            wait_until(lambda: not each.alive, 10, "the controller's end")
            logs.setdefault(setting, []).append(each.controller_log())
    assert all("warm-up: windows" not in log for log in logs["0"]), logs["0"]
    assert shared or "warm-up: windows" in logs["report"][0], logs["report"]


def test_two_controllers_at_once_are_two_processes_of_the_same_server(tmp_path: Path) -> None:
    with client(tmp_path, "a") as one, client(tmp_path, "b") as two:
        assert one.pid != two.pid and moves(one) and moves(two)
        assert parent_of(one.pid) == parent_of(two.pid) == launcher._server.process.pid


def test_a_controller_holds_its_own_descriptors_alone_and_blocks_no_signal(
        tmp_path: Path) -> None:
    """A fork of the server inherits what the server holds: each of two controllers at once
    holds /dev/null, its stderr, its channel and its own segment, and neither the server's
    socket (a controller could ask it for processes) nor the server's pidfd of the other."""
    with client(tmp_path, "a") as one, client(tmp_path, "b") as two:
        for each in (one, two):
            held = {fd: os.readlink(f"/proc/{each.pid}/fd/{fd}")
                    for fd in os.listdir(f"/proc/{each.pid}/fd")}
            assert {held["0"], held["1"]} == {os.devnull}, held
            assert held["2"].endswith("(deleted)"), held  # its log: an unnamed temporary file
            sockets = [what for what in held.values() if what.startswith("socket:")]
            others = set(held.values()) - {os.devnull, held["2"], *sockets}
            assert len(sockets) == 1 and others == {f"/dev/shm/{each.segment_name}"}, held
            status = Path(f"/proc/{each.pid}/status").read_text()
            assert "SigBlk:\t0000000000000000" in status


def test_a_controllers_end_is_told_with_its_code_and_a_closed_one_ends_with_0(
        tmp_path: Path) -> None:
    with client(tmp_path, "killed") as killed:
        process = killed.link.process
        os.kill(killed.pid, signal.SIGKILL)
        assert process.wait(timeout=10) == -signal.SIGKILL
        assert killed.link.exited() == f"the control process exited (code {-signal.SIGKILL})"
    closed = client(tmp_path, "closed")
    closed.close()
    assert closed.link.process.returncode == 0


def test_a_dead_server_is_started_again_and_its_controllers_run_on(tmp_path: Path) -> None:
    with client(tmp_path, "before") as before:
        old = launcher._server
        assert old is not None
        old.process.kill()
        old.process.wait(timeout=10)
        assert moves(before), "the controller of a dead server runs on"
        with client(tmp_path, "after") as after:
            assert launcher._server is not old
            assert parent_of(after.pid) == launcher._server.process.pid and moves(after)
            assert moves(before)
        process = before.link.process
    assert process.returncode == launcher.LOST_CODE  # the server that would tell is gone
    assert not shm.pid_alive(process.pid)


def test_a_malformed_request_is_refused_with_its_reason_and_the_server_serves_on(
        tmp_path: Path) -> None:
    server = launcher.ForkServer(_child_env())
    try:
        ours, theirs = socket.socketpair()
        with ours, theirs, tempfile.TemporaryFile() as err:
            for request, why in ((b"[1, 2]", "a request is"), (b"\xff", "refused request"),
                                 (json.dumps({"config": "{}", "env": {}, "cwd": "/"}).encode(),
                                  "ProcessConfig")):
                with pytest.raises(ControllerError, match=why):
                    server.launch(request, [theirs.fileno(), err.fileno()], 10)
            assert server.alive
    finally:
        server.sock.close()
        server.process.wait(timeout=10)
    assert server.process.returncode == 0, server.log()


def test_a_request_too_long_or_refused_at_length_is_an_error_and_the_server_serves_on(
        tmp_path: Path) -> None:
    """A request longer than the socket carries was taken for the server's end (another
    server started, the first left running); a refusal quoting a long request overran the
    client's answer buffer (JSONDecodeError, not ControllerError)."""
    server = launcher.ForkServer(_child_env())
    try:
        ours, theirs = socket.socketpair()
        with ours, theirs, tempfile.TemporaryFile() as err:
            fds = [theirs.fileno(), err.fileno()]
            too_long = json.dumps({"config": "{}", "env": {"X": "x" * (8 << 20)}, "cwd": "/"})
            with pytest.raises(ControllerError, match="more than the fork server's socket"):
                server.launch(too_long.encode(), fds, 10)
            long_key = json.dumps({"config": json.dumps({"k" * 10_000: 1}), "env": {},
                                   "cwd": "/"})
            with pytest.raises(ControllerError, match="unexpected keyword argument 'kkk"):
                server.launch(long_key.encode(), fds, 10)
            assert server.alive
    finally:
        server.sock.close()
        server.process.wait(timeout=10)
    assert server.process.returncode == 0, server.log()


def test_the_server_ends_with_the_client_that_started_it(tmp_path: Path) -> None:
    """A client killed outright: its server sees its end of the socket close and exits (its
    controller's own watch stops the controller, as before)."""
    script = f"""
from control import ControlClient, launcher
client = ControlClient("rig", lockstep=True, data_dir={str(tmp_path)!r}, orphan_timeout_s=0.5)
print(launcher._server.process.pid, client.pid, flush=True)
input()
"""
    with subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True) as doomed:
        assert doomed.stdout is not None
        server_pid, controller_pid = map(int, doomed.stdout.readline().split())
        doomed.kill()
        doomed.wait(timeout=10)
        wait_until(lambda: not shm.pid_alive(server_pid), 10, "the server's end")
        wait_until(lambda: not shm.pid_alive(controller_pid), 30, "the orphaned controller's end")
