"""``servodesk controller`` and the clients that attach to it, all real processes: one holds
command, the others observe and are refused with the reason, any may E-stop, and a
commander that dies leaves a holding controller that another client can take."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import stat
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest

from control import rendezvous
from control.attached import NotCommanding
from control.client import ControlClient, ControllerError
from control.rt import shm
from control.rt.commands import Hold
from control.rt.events import Refused
from control.rt.layout import Mode
from control.rt.wire import Broken, Wire
from tests.control.doomed_client import DOOMED

ROOT = Path(__file__).resolve().parents[2]


def until(condition: Callable[[], object], timeout: float = 10.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what or condition}")
        time.sleep(0.01)


def nudged(client: ControlClient, joint: int, by: float) -> list[float]:
    q = list(client.status().position)
    q[joint] += by
    return q


def test_observers_are_refused_with_the_reason_and_command_is_handed_over(
        controller_service) -> None:
    a = ControlClient.attach(controller_service.socket, name="a")
    b = ControlClient.attach(controller_service.socket, name="b")
    try:
        with pytest.raises(NotCommanding, match="observing: nobody holds command; take it first"):
            a.hold()
        a.take_command()
        assert a.role == "commanding"
        until(lambda: b.holder == a.name, what="b told that a commands")
        assert b.role == f"observing: command is held by {a.name}"
        held = re.escape(f"command is held by {a.name}; take it first")
        with pytest.raises(NotCommanding, match=held):
            b.jog([5.0] * 6)
        with pytest.raises(NotCommanding, match=re.escape(f"{a.name} holds command; it must")):
            b.take_command()
        # a script that skips the client's own check is refused by the service, with the reason
        script = rendezvous.connect(controller_service.socket)
        script.send(rendezvous.Join("script", os.getpid()))
        assert isinstance(script.recv().record, rendezvous.Hello)
        script.send(Hold())
        until(lambda: script.poll(0.1), what="the script's refusal")
        refusal = script.recv().record
        while not isinstance(refusal, Refused):
            refusal = script.recv().record
        assert refusal.reason == f"observing: command is held by {a.name}; take it first"
        script.close()
        a.release_command()
        until(lambda: not b.holder, what="b told that command is free")
        b.take_command()
        until(lambda: a.holder == b.name, what="a told that b commands")
        with pytest.raises(NotCommanding, match=re.escape(f"held by {b.name}")):
            a.go_to(nudged(a, 0, 2.0))
        result = b.wait(b.go_to(nudged(b, 0, 2.0)), timeout=60)
        assert result.complete, result.status
        assert result.files is not None and result.files.json.parent == \
            controller_service.data_dir
        assert result.move_id >= rendezvous.ID_SPAN  # b's numbers, clear of every other's
    finally:
        a.close()
        b.close()
    assert controller_service.proc.poll() is None  # detaching leaves the controller running


def test_an_estop_from_an_observer_latches(controller_service) -> None:
    commander = ControlClient.attach(controller_service.socket, name="commander")
    observer = ControlClient.attach(controller_service.socket, name="observer")
    try:
        commander.take_command()
        observer.estop()
        until(lambda: commander.status().estop, timeout=5, what="the observer's E-stop")
        with pytest.raises(NotCommanding):
            observer.reset()  # releasing the latch is the commander's
        commander.wait_event("estop", match=lambda e: e.payload["latched"])
        commander.reset()
        commander.wait_event("estop", timeout=5, match=lambda e: not e.payload["latched"])
    finally:
        commander.close()
        observer.close()


def test_the_commander_killed_mid_move_leaves_a_holding_controller_another_can_take(
        controller_service) -> None:
    watcher = ControlClient.attach(controller_service.socket, name="watcher")
    doomed = subprocess.Popen([sys.executable, "-c", DOOMED, str(controller_service.socket)],
                              cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert doomed.stdout is not None
        name = doomed.stdout.readline().strip()
        assert name.startswith("doomed #"), name
        until(lambda: watcher.status().mode == Mode.FOLLOW_TRACK, what="the doomed move")
        os.kill(doomed.pid, signal.SIGKILL)
        doomed.wait(timeout=30)
        released = watcher.wait_event("commander", timeout=10,
                                      match=lambda e: e.payload["holder"] == "")
        assert released.message.startswith(f"{name} left: command released")
        until(lambda: watcher.status().mode == Mode.HOLD, timeout=5, what="the controller to hold")
        tick = watcher.status().tick
        until(lambda: watcher.status().tick > tick + 100, what="the controller to keep ticking")
        # the dead client's run is saved by the service
        until(lambda: any(json.loads(p.read_text())["kind"] == "go_to"
                          for p in controller_service.data_dir.glob("*.json")),
              what="the dead client's run")
        watcher.take_command()
        result = watcher.wait(watcher.go_to(nudged(watcher, 1, 2.0)), timeout=60)
        assert result.complete, result.status
    finally:
        if doomed.poll() is None:
            doomed.kill()
        watcher.close()
    assert not any(name.startswith(f"{shm.PREFIX}{doomed.pid}_") for name in
                   shm.leftover_segments())  # the dead client's move segment was saved, unlinked


def test_a_silent_commander_loses_command_and_the_controller_holds_and_runs_on(
        controller_service) -> None:
    silent = ControlClient.attach(controller_service.socket, name="silent")
    watcher = ControlClient.attach(controller_service.socket, name="watcher")
    try:
        silent.take_command()
        silent.jog([20.0, 0, 0, 0, 0, 0])
        until(lambda: watcher.status().mode == Mode.MANUAL_ACTUATE, what="the jog")
        silent.heartbeat_on = False  # frozen: its socket stays open, its heartbeat stops
        lost = watcher.wait_event("fault", timeout=10, match=lambda e: e.payload["kind"] ==
                                  "ui_lost")
        assert "holding position" in lost.message
        assert watcher.status().mode == Mode.HOLD
        released = watcher.wait_event("commander", timeout=10,
                                      match=lambda e: e.payload["holder"] == "")
        assert released.message == (f"{silent.name} silent for 3 s: command released, the "
                                    "controller holds")
        tick = watcher.status().tick
        until(lambda: watcher.status().tick > tick + 100, what="the controller to keep ticking")
        with pytest.raises(NotCommanding, match="nobody holds command"):
            silent.jog([20.0, 0, 0, 0, 0, 0])
        watcher.take_command()
        watcher.hold()
    finally:
        silent.close()
        watcher.close()
    assert controller_service.proc.poll() is None


def test_a_set_the_commander_gives_is_the_one_a_later_client_sees(controller_service) -> None:
    commander = ControlClient.attach(controller_service.socket, name="tuner")
    try:
        commander.take_command()
        hold = commander.machine.hold
        softer = replace(hold, duty_limit=hold.duty_limit * 0.9)
        assert commander.set_coefficients("hold", softer).ok
        later = ControlClient.attach(controller_service.socket, name="later")
        try:
            assert later.coefficients["hold"].duty_limit == softer.duty_limit
            assert later.coefficients["track"] is later.machine.track  # untouched: by its name
            with pytest.raises(NotCommanding, match="take it first"):
                later.set_coefficients("hold", hold)  # refused before it is written
            again = ControlClient.attach(controller_service.socket, name="again")
            assert again.coefficients["hold"].duty_limit == softer.duty_limit
            again.close()
        finally:
            later.close()
    finally:
        commander.close()


def test_the_socket_is_the_owners_alone_and_a_wrong_key_is_refused(controller_service) -> None:
    socket_path = controller_service.socket
    assert stat.S_IMODE(os.stat(socket_path.parent).st_mode) == 0o700
    assert stat.S_IMODE(os.stat(socket_path).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(rendezvous.key_path(socket_path)).st_mode) == 0o600
    assert stat.S_ISSOCK(os.stat(socket_path).st_mode)
    with socket.socket(socket.AF_UNIX) as stranger:
        stranger.connect(str(socket_path))
        wire = Wire(stranger, rendezvous.CODEC, rendezvous.EVENT_LIMIT)
        with pytest.raises((Broken, PermissionError)):
            rendezvous.authenticate(wire, b"not the key", time.monotonic() + 10, serving=False)
    client = ControlClient.attach(socket_path, name="rightful")  # the service serves on
    client.close()


def test_a_second_service_on_the_socket_is_refused_and_sigterm_cleans_up(
        controller_service, tmp_path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT),
           "XDG_RUNTIME_DIR": str(controller_service.runtime)}
    second = subprocess.run([sys.executable, "-m", "app", "controller"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=120)
    assert second.returncode == 2
    assert "a controller service already listens on" in second.stderr
    client = ControlClient.attach(controller_service.socket, name="last")
    segment = client.segment_name
    assert controller_service.stop() == 0
    until(lambda: client.dead, what="the client to notice the service stopped")
    # the service stops its controller, then closes its connections: either is seen first
    assert ("the controller service closed its connection" in client.dead
            or "the control process is gone" in client.dead), client.dead
    assert "start `servodesk controller` again, then attach" in client.dead
    with pytest.raises(ControllerError):
        client.hold()
    client.close()
    assert not controller_service.socket.exists()
    assert not rendezvous.key_path(controller_service.socket).exists()
    assert segment not in shm.leftover_segments()


def test_attach_without_a_service_says_how_to_start_one(tmp_path) -> None:
    with pytest.raises(ConnectionError, match="start one with `servodesk controller`"):
        ControlClient.attach(tmp_path / "controller.sock")
