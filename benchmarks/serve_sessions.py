"""Many browser sessions of ``servodesk serve`` at once, beside a CPU burner (issue 22): does the
controller service, which beats the controller's heartbeat while nobody commands, stay heard?

    python benchmarks/serve_sessions.py [--sessions 20] [--hold 200] [--max-sessions 4]
                                        [--no-burner]

``servodesk serve`` starts its own controller (the simulated Unimate 2000B, real time, the
default 250 ms heartbeat allowance); a watcher attaches; a burner takes a core; then
``--sessions`` websockets open at once as the page opens them (tests/app/browser.py's
``ScriptedSessions``: its Origin, the token). Printed: how many were admitted and refused, how
long until every admitted TUI showed its screen, and over that and ``--hold`` more seconds:
the controller's client-silent holds (``ui_lost``), the heartbeat's longest age as the
controller sees it (read from shared memory by another process), whether the controller is
alive, the sessions' CPU use and the nice values of the service and a session's TUI.
``--sessions 0`` is the baseline: the same machine, no session.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ui import start_burner, watch_heartbeat  # noqa: E402  (benchmarks/ui.py)

from control.client import ControlClient, Event  # noqa: E402
from tests.app.browser import Served, Session, scripted  # noqa: E402

SCREEN = "observing: nobody holds command"
UP_S = 300.0  # twenty TUIs starting at once on a loaded two-core machine


def session_pids(socket: Path) -> list[int]:
    """The sessions' TUIs: ``python -m app --attach SOCKET`` processes."""
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"--attach" in argv and os.fsencode(socket) in argv:
            pids.append(int(entry.name))
    return pids


def cpu_s(pids: list[int]) -> float:
    """User and system CPU seconds the processes ``pids`` have used."""
    ticks = 0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        ticks += int(fields[11]) + int(fields[12])  # utime, stime
    return ticks / os.sysconf("SC_CLK_TCK")


def run(sessions: int, hold_s: float, max_sessions: int, burner: bool) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        served = Served(Path(tmp) / "serve.log", "--data-dir", str(Path(tmp) / "runs"),
                        "--max-sessions", str(max_sessions))
        faults: list[Event] = []
        watcher = ControlClient.attach(served.socket, name="benchmark",
                                       on_event=lambda e: faults.append(e)
                                       if e.kind == "fault" else None)
        parent, child = mp.Pipe()
        heartbeat = mp.Process(target=watch_heartbeat,
                               args=(watcher.segment_name, watcher.machine.n_joints, child))
        heartbeat.start()
        parent.recv()
        burning = start_burner() if burner else None
        try:
            with scripted(served) as scripts:
                started = time.monotonic()
                opened = scripts.open(sessions) if sessions else []
                running = [s for s in opened if isinstance(s, Session)]
                refused = [s for s in opened if not isinstance(s, Session)]
                deadline = time.monotonic() + UP_S
                while (not all(SCREEN in s.text() for s in running)
                       and time.monotonic() < deadline and watcher.alive):
                    time.sleep(0.1)
                up_s = time.monotonic() - started
                pids = session_pids(served.socket)
                cpu_before, hold_started = cpu_s(pids), time.monotonic()
                deadline = hold_started + hold_s
                while time.monotonic() < deadline and watcher.alive:
                    time.sleep(0.1)
                held_s = time.monotonic() - hold_started
                cpu = (cpu_s(pids) - cpu_before) / held_s
                nice = [os.getpriority(os.PRIO_PROCESS, pid) for pid in pids[:1]]
            alive = watcher.alive
            service_nice = os.getpriority(os.PRIO_PROCESS, watcher.service_pid)
        finally:
            if burning is not None:
                burning.kill()
                burning.wait()
            parent.send("stop")
            oldest_ms = parent.recv()
            heartbeat.join()
            watcher.close()
            served.stop()
    silent = sum(1 for f in faults if f.payload["kind"] == "ui_lost")
    print(f"servodesk serve --max-sessions {max_sessions}, {sessions} sessions at once"
          f"{' beside a burner' if burner else ''}: {len(running)} admitted, {len(refused)} "
          f"refused ({', '.join(sorted({str(s) for s in refused})) or 'none'}); every admitted "
          f"screen shown in {up_s:.1f} s")
    print(f"  over that and {held_s:.0f} s more: {silent} client-silent holds (ui_lost), the "
          f"heartbeat's longest age {oldest_ms:.0f} ms (the controller holds at 250), "
          f"controller {'alive' if alive else 'DEAD'}")
    print(f"  sessions' CPU {cpu * 100:.0f} % of a core in all; nice: service "
          f"{service_nice}, a session's TUI {nice[0] if nice else '-'}; load average "
          f"{os.getloadavg()[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=int, default=20)
    parser.add_argument("--hold", type=float, default=200.0, metavar="S",
                        help="seconds to keep them open once every admitted one shows")
    parser.add_argument("--max-sessions", type=int, default=4)
    parser.add_argument("--no-burner", action="store_true")
    args = parser.parse_args()
    run(args.sessions, args.hold, args.max_sessions, not args.no_burner)


if __name__ == "__main__":
    main()
