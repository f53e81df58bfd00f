"""``python -m app`` in a detached tmux session of a fixed size, driven with send-keys and
read back with capture-pane: the real-terminal tests' (test_smoke_tmux.py) and the soak's
(soak.py). Each user of it has a tmux server of its own (``socket``), so one's clean-up
never ends another's session.

Every wait polls capture-pane for the content it expects, with a deadline generous enough
for a loaded two-core machine, and fails with ``TerminalError`` showing the last screen.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

TMUX = shutil.which("tmux")
REPO = Path(__file__).resolve().parents[2]
WIDTH, HEIGHT = 160, 48
START_S = 120.0  # startup to a live screen: ~1.5 s measured, generous for a loaded machine
WAIT_S = 60.0  # a key's effect on the screen: well under a second unloaded
TMUX_S = 30.0  # one tmux command


class TerminalError(AssertionError):
    """A wait that failed: what was awaited, and the screen at the end."""


def tmux(socket: str, *args: str) -> str:
    assert TMUX is not None, "tmux is not installed"
    done = subprocess.run([TMUX, "-L", socket, "-f", os.devnull, *args], capture_output=True,
                          text=True, timeout=TMUX_S)
    if done.returncode:
        raise RuntimeError(f"tmux {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


def kill_server(socket: str) -> None:
    if TMUX is not None:
        subprocess.run([TMUX, "-L", socket, "kill-server"], capture_output=True, timeout=TMUX_S)


class Terminal:
    poll_s = 0.05  # between screen reads while waiting: each a tmux process

    def __init__(self, socket: str, session: str, status_file: Path) -> None:
        self.socket = socket
        self.session = session
        self.status_file = status_file

    def screen(self) -> str:
        return tmux(self.socket, "capture-pane", "-p", "-t", self.session)

    def exit_status(self) -> int | None:
        """The app's exit status once it has exited, else None: the session's shell writes
        it to a file (tmux may mark the pane dead before it learns the status)."""
        text = self.status_file.read_text() if self.status_file.exists() else ""
        return int(text) if text.endswith("\n") else None

    def keys(self, *keys: str) -> None:
        tmux(self.socket, "send-keys", "-t", self.session, *keys)

    def tmux_format(self, text: str) -> str:
        """``text`` with tmux's formats (``#{pane_pid}``, …) filled in for this session."""
        return tmux(self.socket, "display", "-p", "-t", self.session, text).strip()

    def size(self) -> str:
        return self.tmux_format("#{window_width}x#{window_height}")

    def wait(self, shows: Callable[[str], bool], what: str, timeout: float = WAIT_S) -> str:
        """Poll the screen until ``shows(screen)``; fail with the last screen after
        ``timeout`` or as soon as the app has exited (unless that is what was awaited)."""
        deadline = time.monotonic() + timeout
        while True:
            screen = self.screen()
            if shows(screen):
                return screen
            if self.exit_status() is not None:
                raise TerminalError(f"the app exited while waiting for {what}; the terminal "
                                    f"shows:\n{screen}")
            if time.monotonic() > deadline:
                raise TerminalError(f"the terminal never showed {what} within {timeout:g} s; "
                                    f"it shows:\n{screen}")
            time.sleep(self.poll_s)

    def quit_latched(self) -> None:
        """Quit with the E-stop latched: the app asks first, then exits with status 0."""
        self.keys("C-q")
        self.wait(lambda s: "Quit servodesk?" in s and "E-stop is latched" in s,
                  "the quit question")
        self.keys("y")
        deadline = time.monotonic() + WAIT_S
        while self.exit_status() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if self.exit_status() != 0:
            raise TerminalError(f"quit gave exit status {self.exit_status()}; the terminal "
                                f"shows:\n{self.screen()}")


def launch(socket: str, session: str, tmp_path: Path, *options: str) -> Terminal:
    """``python -m app`` (with ``options``) in a new detached tmux session of WIDTH ×
    HEIGHT, saving under ``tmp_path/data``; remain-on-exit keeps the last screen for a
    failure message if the app exits early."""
    status = tmp_path / "exit-status"
    # pytest's COLUMNS=80 LINES=24 would reach the app through the tmux server, and Textual
    # takes them over the pane's size: the app gets the pane's
    command = (f"cd {shlex.quote(str(REPO))} && env -u COLUMNS -u LINES "
               f"PYTHONPATH={shlex.quote(str(REPO))} "
               f"{shlex.quote(sys.executable)} -m app --data-dir "
               f"{shlex.quote(str(tmp_path / 'data'))} {shlex.join(options)}; "
               f"echo $? > {shlex.quote(str(status))}")
    tmux(socket, "start-server", ";", "set-option", "-g", "remain-on-exit", "on", ";",
         "new-session", "-d", "-s", session, "-x", str(WIDTH), "-y", str(HEIGHT), command)
    return Terminal(socket, session, status)
