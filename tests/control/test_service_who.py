"""Who did what, when several clients attach to ``servodesk controller`` (issue 26 item 5), on
real processes: an observer's E-stop reaches the commander named for the observer; command
taken, released and lost (a commander killed mid-move) is said as such, and the observer's
event log records each, the killed commander's move ending as interrupted, not aborted."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Callable

from app.event_log import entries_of
from control.client import ControlClient, Event
from control.rt.events import Commander, EStop, MoveDone
from control.rt.layout import Mode
from tests.conftest import ROOT
from tests.control.doomed_client import DOOMED
from tests.control.waiting import wait_until


def until(condition: Callable[[], object], what: str, timeout: float = 10.0) -> None:
    wait_until(lambda: bool(condition()), timeout, what)


def attached(socket, name: str) -> tuple[ControlClient, list[Event]]:
    """A client attached as ``name``, and every event it receives from now on."""
    client = ControlClient.attach(socket, name=name)
    seen: list[Event] = []
    client.on_event = seen.append
    return client, seen


def records(seen: list[Event], kind: type) -> list:
    return [e.record for e in list(seen) if isinstance(e.record, kind)]


def test_the_events_say_who_pressed_estop_and_who_took_released_or_lost_command(
        controller_service) -> None:
    commander, commanders = attached(controller_service.socket, "bench")
    observer, observers = attached(controller_service.socket, "watcher")
    doomed = None
    try:
        commander.take_command()
        until(lambda: records(observers, Commander), what="the observer told who commands")
        assert records(observers, Commander)[-1] == Commander(
            commander.name, f"{commander.name} took command", "taken")

        # the observer presses E-stop: the commander hears who
        observer.estop()
        until(lambda: any(observer.name in r.reason for r in records(commanders, EStop)),
              what="the E-stop named for the observer")
        named = [r for r in records(commanders, EStop) if observer.name in r.reason]
        assert set(named) == {EStop(True, f"operator E-stop from {observer.name}")}, named
        commander.reset()
        until(lambda: not commander.status().estop, what="the release")
        commander.release_command()
        until(lambda: records(observers, Commander)[-1].change == "released",
              what="the release of command")

        # a commander killed mid-move: command lost, its move interrupted, in the log
        doomed = subprocess.Popen([sys.executable, "-c", DOOMED, str(controller_service.socket)],
                                  cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert doomed.stdout is not None
        name = doomed.stdout.readline().strip()
        until(lambda: observer.status().mode == Mode.FOLLOW_TRACK, what="the doomed move")
        os.kill(doomed.pid, signal.SIGKILL)
        until(lambda: records(observers, Commander)[-1].change == "lost", what="command lost")
        until(lambda: records(observers, MoveDone), what="the doomed move's end")
        log = [entry for event in list(observers)
               for entry in entries_of(event.record, observer.machine)]
        lines = [f"{e.kind}: {e.what}" for e in log]
        assert f"command: {commander.name} took command" in lines, lines
        assert f"E-stop: latched: operator E-stop from {observer.name}" in lines, lines
        assert f"command: {commander.name} released command; the controller holds" in lines
        assert f"command: {name} took command" in lines, lines
        assert any(line.startswith(f"command lost: {name} left") for line in lines), lines
        (end,) = [line for line in lines if line.startswith("move end")]
        assert end.endswith(f"interrupted: the commanding client ({name}) left"), end
    finally:
        if doomed is not None and doomed.poll() is None:
            doomed.kill()
        observer.close()
        commander.close()
