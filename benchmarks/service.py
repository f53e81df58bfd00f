"""The controller as a service (control/service.py): how long ``servodesk controller`` takes
from its start to its socket being ready, how long ``ControlClient.attach`` takes, and the
round trip of taking and releasing command.

    python benchmarks/service.py [--repeat 5]

Each repeat starts ``python -m app controller`` (the simulated Unimate 2000B, real time) in
a fresh runtime directory, waits for the socket, attaches ten clients one after the other,
takes and releases command with each, and stops the service with SIGTERM.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from control.client import ControlClient  # noqa: E402

ATTACHES = 10


def one_service() -> tuple[float, list[float], list[float]]:
    """(start to socket s, attach times s, take + release times s) of one service."""
    runtime = Path(tempfile.mkdtemp(prefix="sd-"))
    socket_path = runtime / "servodesk" / "controller.sock"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_RUNTIME_DIR": str(runtime)}
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "app", "controller", "--data-dir",
                             str(runtime / "runs")], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while not socket_path.exists():
            if proc.poll() is not None:
                raise SystemExit("servodesk controller exited before its socket appeared")
            time.sleep(0.002)
        ready = time.monotonic() - started
        attaches, commands = [], []
        for _ in range(ATTACHES):
            t0 = time.monotonic()
            client = ControlClient.attach(socket_path, name="benchmark")
            attaches.append(time.monotonic() - t0)
            t0 = time.monotonic()
            client.take_command()
            client.release_command()
            commands.append(time.monotonic() - t0)
            client.close()
        return ready, attaches, commands
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
        shutil.rmtree(runtime, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    ready, attaches, commands = [], [], []
    for _ in range(args.repeat):
        r, a, c = one_service()
        ready.append(r)
        attaches += a
        commands += c

    def figures(values: list[float]) -> str:
        ms = sorted(v * 1e3 for v in values)
        return (f"median {statistics.median(ms):7.1f} ms  min {ms[0]:7.1f}  "
                f"max {ms[-1]:7.1f}  (n={len(ms)})")

    print(f"servodesk controller start to socket ready: {figures(ready)}")
    print(f"ControlClient.attach:                       {figures(attaches)}")
    print(f"take_command + release_command:             {figures(commands)}")


if __name__ == "__main__":
    main()
