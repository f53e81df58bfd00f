"""``servodesk serve`` in a real headless Chromium: the tabs render, live values change, an
observe-only session's jog and take-command are refused (a script attached beside it sees
the joints still held, no jog) while its E-stop latches, and with ``--command`` the session
takes command at start and its E-stop latches; serve stops the controller it started.

What the browser shows is read from what it received (tests/app/browser.py): the terminal is
drawn on a canvas."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from selenium.webdriver.common.keys import Keys

from app.cli import main
from control.attached import AttachedClient
from control.client import ControlClient
from control.layout import Mode
from tests.app.browser import ROOT, Browser, Served, browser, wait_until

START_S = 90.0  # serve, a controller, Chromium and a TUI on a loaded two-core machine
STEP_S = 30.0
TICK = re.compile(r"tick (\d+)")


@pytest.fixture
def page() -> Iterator[Browser]:
    with browser() as opened:
        yield opened


@pytest.fixture
def served(tmp_path: Path) -> Iterator[list[Served]]:
    """Serve processes the test starts, stopped (SIGTERM: their controllers too) at teardown."""
    started: list[Served] = []
    yield started
    for serve in started:
        serve.stop()


def attach(socket: Path) -> AttachedClient:
    return ControlClient.attach(socket, name="test script")


def ticks(page: Browser, after: int) -> int:
    """The header's newest tick count received after ``after``."""
    return int(TICK.findall(page.text()[after:])[-1])


def test_an_observe_only_session_shows_live_tabs_and_refuses_commands_but_not_estop(
        controller_service, served, page, tmp_path) -> None:
    serve = Served(tmp_path / "serve.log", "--socket", str(controller_service.socket),
                   runtime=controller_service.runtime)
    served.append(serve)
    page.open(serve.url)
    page.wait_for("observing: nobody holds command", START_S)
    for title in ("F1 Jog", "F2 Moves", "F7 Latency", "F10 Log", "E-STOP", "take command"):
        page.wait_for(title, STEP_S)  # the tabs and the footer
    first = int(page.wait_for(TICK, STEP_S).group(1))
    mark = page.mark()
    wait_until(lambda: TICK.search(page.text()[mark:]) is not None
               and ticks(page, mark) > first, STEP_S, "a later tick in the header")

    mark = page.mark()
    page.press(Keys.F7)
    page.wait_for("Run a fresh test", STEP_S, after=mark)  # the Latency tab's content
    mark = page.mark()
    page.press(Keys.F1)
    page.wait_for("increment", STEP_S, after=mark)  # the Jog tab's

    script = attach(controller_service.socket)
    try:
        mark = page.mark()
        page.press("a")  # In/Out out, on the Jog tab
        page.wait_for("take it first", STEP_S, after=mark)  # its notification
        assert script.status().mode == Mode.HOLD  # no jog reached the valves: the joints hold
        mark = page.mark()
        page.press_ctrl("k")
        page.wait_for("observes only", STEP_S, after=mark)
        assert script.holder == ""  # nobody took command
        page.press_ctrl("e")
        wait_until(lambda: script.status().estop, STEP_S, "the observer's E-stop latched")
    finally:
        script.close()
    assert serve.stop() == 0
    assert controller_service.proc.poll() is None  # serve attached: the controller runs on


def test_with_command_the_session_commands_and_its_estop_latches(served, page, tmp_path
                                                                 ) -> None:
    serve = Served(tmp_path / "serve.log", "--command", "--data-dir", str(tmp_path / "runs"))
    served.append(serve)
    page.open(serve.url)
    page.wait_for("COMMANDING", START_S)
    script = attach(serve.socket)
    try:
        assert script.holder.startswith("servodesk TUI")
        mark = page.mark()
        page.press(Keys.ESCAPE)
        wait_until(lambda: script.status().estop, STEP_S, "the session's E-stop latched")
        page.wait_for("Every valve is closed", STEP_S, after=mark)  # the banner
        assert serve.stop() == 0
        # the controller serve started is stopped with it
        wait_until(lambda: not script.alive, STEP_S, "the controller stopped with serve")
    finally:
        script.close()


def test_a_taken_port_is_a_clear_error_and_the_controller_started_for_it_stops(tmp_path
                                                                               ) -> None:
    runtime = Path(tempfile.mkdtemp(prefix="sd-"))
    try:
        with socket.socket() as taken:
            taken.bind(("127.0.0.1", 0))
            taken.listen()
            port = taken.getsockname()[1]
            done = subprocess.run(
                [sys.executable, "-m", "app", "serve", "--data-dir", str(tmp_path / "runs"),
                 "--http-port", str(port)], cwd=ROOT,
                env={**os.environ, "PYTHONPATH": str(ROOT), "XDG_RUNTIME_DIR": str(runtime)},
                capture_output=True, text=True, timeout=START_S)
        assert done.returncode == 2
        assert f"cannot listen on 127.0.0.1:{port}" in done.stderr
        assert "servodesk controller: stopped" in done.stderr  # not left running
    finally:
        shutil.rmtree(runtime, ignore_errors=True)


@pytest.mark.parametrize("options", [["--observe-only"], ["--take-command"],
                                     ["--attach", "--observe-only", "--take-command"]])
def test_the_command_options_of_an_attached_tui_are_checked(options, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(options)
    assert exited.value.code == 2
    assert "--observe-only and --take-command" in capsys.readouterr().err
