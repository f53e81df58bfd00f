"""The TUI in a real terminal: ``python -m app`` in a detached tmux session of a fixed
size, driven with send-keys and read back with capture-pane. Keys go through the
terminal, Textual's input parser (a lone Escape after its escape-sequence timeout) and
the controller; the screen is what an operator sees.

Every wait polls capture-pane for the content it expects, with a deadline generous
enough for a loaded two-core machine, and each key is sent only once the screen shows
the previous one's effect: nothing here waits for time, and nothing asserts how long
a step took (the time to a live screen is printed, not judged). The five-minute soak beside
a CPU burner drives the same app in the same terminal (tests/app/soak.py), as a benchmark:
``python -m benchmarks.ui --soak 300``.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from tests.app.terminal import HEIGHT, START_S, TMUX, WAIT_S, WIDTH, kill_server, launch

SOCKET = f"servodesk-smoke-{os.getpid()}"  # a tmux server of our own: no one else's settings

pytestmark = pytest.mark.skipif(
    TMUX is None, reason="tmux is not installed: the real-terminal smoke test needs it "
                         "(apt-get install tmux; .ci/run installs it)")


def jog_duty(screen: str, duty: str) -> bool:
    """Whether the Jog tab's In/Out row (keys a/z) shows ``duty``."""
    return any(line.lstrip().startswith("a/z") and duty in line for line in screen.splitlines())


def test_servodesk_runs_in_a_real_terminal(tmp_path: Path) -> None:
    started = time.monotonic()
    term = launch(SOCKET, "smoke", tmp_path)
    assert term.size() == f"{WIDTH}x{HEIGHT}"
    try:
        screen = term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
        live_after = time.monotonic() - started
        for tab in ("F1 Jog", "F2 Moves", "F3 Scope", "F4 Status", "F5 Tuning", "F6 Runs",
                    "F7 Latency"):
            assert tab in screen
        assert "Unimate 2000B" in screen and "Esc/^E" in screen
        assert "T1 250 mm/s" in screen  # it starts in reduced speed: duty jogs need automatic
        term.keys("C-y")
        term.wait(lambda s: "automatic (full speed)" in s, "the question before automatic")
        term.keys("y")
        term.wait(lambda s: "AUTO" in s and "T1 250 mm/s" not in s, "automatic in the header")
        term.keys("a")  # option.c Manual(): +5 % on In/Out, twice
        term.wait(lambda s: jog_duty(s, "+5"), "In/Out commanded +5 %")
        term.keys("a")
        term.wait(lambda s: jog_duty(s, "+10"), "In/Out commanded +10 %")
        term.keys("Space")
        term.wait(lambda s: not jog_duty(s, "+10"), "In/Out stopped by Space")
        term.keys("F4")
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
        term.quit_latched()
    finally:
        kill_server(SOCKET)
    print(f"live screen {live_after:.2f} s after the session started")


def threads(pid: int) -> int:
    """How many threads process ``pid`` has now."""
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line.split()[1] for line in status.splitlines()
                    if line.startswith("Threads:")))


def test_a_stop_and_continue_from_outside_leaves_one_reader_of_the_terminal(
        tmp_path: Path) -> None:
    """SIGSTOP and SIGCONT from outside (a debugger, ``kill -STOP``): the app goes on with
    the threads it had, and keys work. Textual's own driver started a second input reader and
    a second writer at every SIGCONT (two threads more that never end), and the two readers
    then split the terminal's bytes between them. The thread count is waited for, not timed:
    a worker of the app may come and go meanwhile."""
    term = launch(SOCKET, "stopped", tmp_path)
    try:
        term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
        shell = int(term.tmux_format("#{pane_pid}"))
        pid = int(Path(f"/proc/{shell}/task/{shell}/children").read_text().split()[0])
        before = min(threads(pid) for _ in range(20))
        os.kill(pid, signal.SIGSTOP)
        os.kill(pid, signal.SIGCONT)
        term.keys("C-y")
        term.wait(lambda s: "automatic (full speed)" in s, "the question before automatic")
        term.keys("y")
        term.wait(lambda s: "AUTO" in s and "T1 250 mm/s" not in s, "automatic in the header")
        term.keys("a", "a")
        term.wait(lambda s: jog_duty(s, "+10"), "In/Out commanded +10 %")
        deadline = time.monotonic() + WAIT_S
        while threads(pid) > before and time.monotonic() < deadline:
            time.sleep(0.05)
        assert threads(pid) <= before, f"{threads(pid)} threads after the SIGCONT, {before} before"
        term.keys("Escape")
        term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop from Escape")
        term.quit_latched()
    finally:
        kill_server(SOCKET)
