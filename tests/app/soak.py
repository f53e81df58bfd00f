"""Issue 13's soak: ``python -m app`` in tmux beside a CPU burner, every tab switched to in
turn once a second for ``SOAK_S`` (five minutes), then the app checked live: the Jog tab
shows, the E-stop latches, quit asks and exits 0. What it saw goes into ``soak.json``; the
session's events.jsonl (under ``data``) holds what the controller and the app logged.

It runs in a process of its own, started as soon as the soak test is collected
(tests/app/conftest.py), so its five minutes pass while the quick tests and a few slow
ones that mostly wait run (one busy core at most, besides its own burner) and CI stays
under 15 minutes; the test, ordered after them and before the other slow ones, waits for
it and reads the result::

    python -m tests.app.soak DIRECTORY [SECONDS]
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.app.terminal import REPO, START_S, TerminalError, kill_server, launch

SOAK_S = float(os.environ.get("SERVODESK_SOAK_S", "300"))
TABS = 10  # F1 … F10
RESULT = "soak.json"


def soak(directory: Path, seconds: float) -> dict[str, object]:
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
            time.sleep(1.0)  # the soak's pace, not a wait for an effect
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


class BackgroundSoak:
    """The soak in its own process, writing ``directory/soak.json`` when it is done."""

    def __init__(self, directory: Path, seconds: float = SOAK_S) -> None:
        self.directory = directory
        self.seconds = seconds
        self.process = subprocess.Popen(
            [sys.executable, "-m", "tests.app.soak", str(directory), str(seconds)], cwd=REPO,
            env={**os.environ, "PYTHONPATH": str(REPO)})

    def result(self, timeout: float) -> dict[str, object]:
        """What the soak saw, once it has ended (``subprocess.TimeoutExpired`` if it has
        not within ``timeout``)."""
        self.process.wait(timeout)
        path = self.directory / RESULT
        if not path.exists():
            return {"error": f"the soak exited with {self.process.returncode} and no result"}
        return json.loads(path.read_text())

    def stop(self) -> None:
        """End it early (the suite stopped before the test read it): its clean-up runs."""
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(60)


def main() -> None:
    directory = Path(sys.argv[1])
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else SOAK_S
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # the finally clauses still run
    result = soak(directory, seconds)
    (directory / RESULT).write_text(json.dumps(result))


if __name__ == "__main__":
    main()
