"""Issue 13's soak: ``python -m app`` in tmux beside a CPU burner, every tab switched to in
turn once a second for five minutes, then the app checked live: the Jog tab shows, the
E-stop latches, quit asks and exits 0. It passes when, besides, the tabs were switched once
a second all along and the session's events.jsonl (under ``data``) logged the E-stop and no
"UI lost": the controller, with its real 250 ms heartbeat timeout, never found the client
silent.

Five minutes of wall time is a benchmark's, not the test suite's: it runs as
``python -m benchmarks.ui --soak 300``, which prints what it saw and exits 1 if a check fails.
The real-terminal test (test_smoke_tmux.py) drives the same app through the same terminal.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from app.event_log import FILE as EVENT_FILE
from tests.app.terminal import START_S, TerminalError, kill_server, launch

TABS = 10  # F1 … F10
KEY_S = 1.0  # between two tab switches


def soak(directory: Path, seconds: float) -> dict[str, object]:
    """Run the soak, saving under ``directory/data``; what it saw: ``seconds``, ``switches``,
    ``error`` (empty, or why the app was not live to the end) and the load average."""
    socket = f"servodesk-soak-{os.getpid()}"
    burner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    switches, error = 0, ""
    try:
        term = launch(socket, "soak", directory)
        term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            term.keys(f"F{switches % TABS + 1}")
            switches += 1
            time.sleep(KEY_S)  # the soak's pace, not a wait for an effect
            if term.exit_status() is not None:
                raise TerminalError(f"the app exited during the soak:\n{term.screen()}")
        term.keys("F1")
        term.wait(lambda s: " RUN" in s and "a/z" in s, "the Jog tab, live, after the soak")
        term.keys("Escape")  # an event for the log to show it was kept all along
        term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop")
        term.quit_latched()
    except (TerminalError, RuntimeError, subprocess.TimeoutExpired) as exc:
        error = str(exc)
    finally:
        kill_server(socket)
        burner.kill()
        burner.wait()
    return {"seconds": seconds, "switches": switches, "error": error,
            "load": os.getloadavg()[0]}


def logged(directory: Path) -> list[dict[str, str]]:
    """Every event the soak's session logged (``directory/data/sessions/*/events.jsonl``)."""
    return [json.loads(line) for path in (directory / "data").glob(f"sessions/*/{EVENT_FILE}")
            for line in path.read_text().splitlines()]


def failures(result: dict[str, object], events: list[dict[str, str]]) -> list[str]:
    """The soak's checks that failed, each saying what it saw; empty when it passed."""
    failed = [f"the app was not live to the end: {result['error']}"] if result["error"] else []
    if result["switches"] < result["seconds"] / KEY_S * 0.9:
        failed.append(f"{result['switches']} tab switches in {result['seconds']:g} s: not one "
                      f"every {KEY_S:g} s all along")
    if not any(e["kind"] == "E-stop" for e in events):
        failed.append("the E-stop pressed at the end is not in the session's log")
    failed += [f"the controller found the client silent: {e['time']} {e['what']}"
               for e in events if e["kind"] == "UI lost"]
    return failed
