"""The TUI in a real terminal: ``python -m app`` in a detached tmux session of a fixed
size, driven with send-keys and read back with capture-pane. Keys go through the
terminal, Textual's input parser (a lone Escape after its escape-sequence timeout) and
the controller; the screen is what an operator sees."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

TMUX = shutil.which("tmux")
REPO = Path(__file__).resolve().parents[2]
WIDTH, HEIGHT = 160, 48
SOCKET = f"servodesk-smoke-{os.getpid()}"  # a tmux server of our own: no one else's settings
LIVE_S = 10.0  # startup to a live screen; ~1.5 s measured, generous for a loaded machine

pytestmark = pytest.mark.skipif(
    TMUX is None, reason="tmux is not installed: the real-terminal smoke test needs it "
                         "(apt-get install tmux; .ci/run installs it)")


def tmux(*args: str) -> str:
    done = subprocess.run([TMUX, "-L", SOCKET, "-f", os.devnull, *args], capture_output=True,
                          text=True, timeout=10)
    if done.returncode:
        raise RuntimeError(f"tmux {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


class Terminal:
    def __init__(self, session: str) -> None:
        self.session = session

    def screen(self) -> str:
        return tmux("capture-pane", "-p", "-t", self.session)

    def keys(self, *keys: str) -> None:
        tmux("send-keys", "-t", self.session, *keys)

    def wait(self, shows: Callable[[str], bool], what: str, timeout: float = 20.0) -> str:
        deadline = time.monotonic() + timeout
        while True:
            screen = self.screen()
            if shows(screen):
                return screen
            if time.monotonic() > deadline:
                pytest.fail(f"the terminal never showed {what} within {timeout:g} s; it shows:\n"
                            f"{screen}")
            time.sleep(0.05)


def test_servodesk_runs_in_a_real_terminal(tmp_path: Path) -> None:
    session = f"servodesk-smoke-{os.getpid()}"
    command = (f"cd {shlex.quote(str(REPO))} && PYTHONPATH={shlex.quote(str(REPO))} "
               f"{shlex.quote(sys.executable)} -m app --data-dir "
               f"{shlex.quote(str(tmp_path / 'runs'))}; echo SERVODESK-EXITED $?; sleep 60")
    started = time.monotonic()
    tmux("new-session", "-d", "-s", session, "-x", str(WIDTH), "-y", str(HEIGHT), command)
    term = Terminal(session)
    assert tmux("display", "-p", "-t", session, "#{window_width}x#{window_height}").strip() \
        == f"{WIDTH}x{HEIGHT}"
    try:
        screen = term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", 30)
        live_after = time.monotonic() - started
        assert live_after < LIVE_S
        for tab in ("F1 Jog", "F2 Moves", "F3 Scope", "F4 Status", "F5 Tuning", "F6 Runs",
                    "F7 Latency"):
            assert tab in screen
        assert "Unimate 2000B" in screen and "Esc/^E" in screen
        term.keys("a", "a")  # option.c Manual(): +5 % twice on In/Out
        term.wait(lambda s: any(line.lstrip().startswith("a/z") and "+10" in line
                                for line in s.splitlines()), "In/Out commanded +10 %")
        term.keys("Space", "F4")
        screen = term.wait(lambda s: "end effector" in s, "the Status tab")
        assert "In/Out" in screen and "lateness" in screen
        term.keys("F3")
        term.wait(lambda s: "LIVE" in s and "window 10 s" in s, "the Scope tab")
        term.keys("Escape")
        term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop from Escape")
        term.keys("C-r")
        term.wait(lambda s: "Release the E-stop?" in s, "the release dialog")
        term.keys("y")
        term.wait(lambda s: " RUN" in s and "E-STOP LATCHED" not in s, "the release")
        term.keys("C-e")
        term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop from ctrl+e")
        term.keys("C-q")
        term.wait(lambda s: "SERVODESK-EXITED 0" in s, "a clean exit")
    finally:
        subprocess.run([TMUX, "-L", SOCKET, "kill-server"], capture_output=True, timeout=10)
    print(f"live screen {live_after:.2f} s after the session started")
