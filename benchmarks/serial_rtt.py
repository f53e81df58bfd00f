"""Round trip of the serial backend: DUTY written → its REPORT received, at 1 kHz.

Run: ``PYTHONPATH=. python benchmarks/serial_rtt.py [--seconds 10] [--machine NAME]
[--tcp] [--port URL]``. Without ``--port`` it starts ``servodesk emulate`` on a
pty (or TCP with ``--tcp``) in a child process; with ``--port`` it measures a
real board. Each tick, on an absolute 1 ms grid, it does what the control loop
does (``read``, ``write``) and then waits for the answer to that write, timing
it. Prints the median and p99 round trip, the achieved frame rate, how often
the answer was not in by the next tick, and the link's error counts.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path[:1]:
    sys.path.insert(0, str(ROOT))  # ahead of benchmarks/, whose hw.py would hide the hw package

from hw.machine import load_machine  # noqa: E402
from hw.serial.backend import SerialBackend  # noqa: E402

LAUNCH = ["-m", "app", "emulate"]
PERIOD_NS = 1_000_000


def start_emulator(machine: str, tcp: bool) -> tuple[subprocess.Popen[bytes], str]:
    """``servodesk emulate`` in a child process; returns it and the URL it serves."""
    args = ["--machine", machine, *(["--tcp", "0"] if tcp else [])]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    child = subprocess.Popen([sys.executable, *LAUNCH, *args], cwd=ROOT, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    assert child.stdout is not None
    if not select.select([child.stdout], [], [], 60)[0]:
        child.kill()
        raise SystemExit("the emulator did not start within 60 s")
    return child, child.stdout.readline().decode().strip()


def measure(backend: SerialBackend, seconds: float) -> tuple[list[int], int, float]:
    """Round trips (ns) of every answered tick, ticks whose answer timed out, elapsed s.

    Stops early on a link fault (``backend.fault`` says which).
    """
    n = backend.machine.n_joints
    raw = [0] * n
    duty = [0.0] * n
    rtts: list[int] = []
    missed = 0
    start = time.monotonic_ns()
    deadline = start
    end = start + round(seconds * 1e9)
    while deadline < end:
        backend.clock.sleep_until(deadline)
        backend.read(raw)
        backend.write(duty)
        if backend.wait_reply(0.05):
            rtts.append(backend.rtt_ns)
        else:
            missed += 1
        if backend.fault:
            break
        deadline += PERIOD_NS
        deadline = max(deadline, time.monotonic_ns())
    return rtts, missed, (time.monotonic_ns() - start) / 1e9


def percentile(sorted_values: list[float], p: float) -> float:
    return sorted_values[min(len(sorted_values) - 1, int(p * len(sorted_values)))]


def run(seconds: float = 10.0, machine_name: str = "unimate2000b", port: str | None = None,
        tcp: bool = False) -> dict:
    """Measure ``seconds`` of 1 kHz round trips (the emulator unless ``port``); the figures:
    ``url``, ``elapsed_s``, ``rtts_us`` (sorted), ``missed``, link ``counters``, ``fault``."""
    machine = load_machine(machine_name)
    child, url = (None, port) if port else start_emulator(machine_name, tcp)
    backend = SerialBackend(machine, url, watchdog_s=0.25, open_timeout_s=5.0)
    try:
        backend.open()
        backend.clock.spin_ns = 200_000
        rtts, missed, elapsed = measure(backend, seconds)
    finally:
        backend.close()
        if child is not None:
            child.send_signal(signal.SIGTERM)
            child.wait(timeout=30)
    return {"machine": machine.name, "url": url, "elapsed_s": elapsed,
            "rtts_us": [r / 1e3 for r in sorted(rtts)] or [0.0], "missed": missed,
            "counters": backend.counters.as_dict(), "fault": backend.fault}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--machine", default="unimate2000b")
    parser.add_argument("--port", help="a real board's URL; default: start the emulator")
    parser.add_argument("--tcp", action="store_true", help="emulator on TCP instead of a pty")
    args = parser.parse_args(argv)
    m = run(args.seconds, args.machine, args.port, args.tcp)
    rtts, elapsed, c = m["rtts_us"], m["elapsed_s"], m["counters"]
    print(f"serial round trip, {m['machine']} on {m['url']}, {elapsed:.1f} s at 1 kHz")
    print(f"  DUTY → REPORT: median {percentile(rtts, 0.5):.0f} µs, "
          f"p99 {percentile(rtts, 0.99):.0f} µs, max {rtts[-1]:.0f} µs")
    print(f"  {c['frames_tx'] / elapsed:.0f} frames/s out, {c['frames_rx'] / elapsed:.0f} "
          f"frames/s in; answers later than one tick: {sum(r > PERIOD_NS / 1e3 for r in rtts)}, "
          f"unanswered: {m['missed']}")
    print(f"  errors: crc {c['crc_errors']}, truncated {c['truncated']}, garbage bytes "
          f"{c['garbage_bytes']}, out of order {c['out_of_order']}, link lost {c['link_lost']}, "
          f"watchdog trips {c['watchdog_trips']}")
    if m["fault"]:
        print(f"  stopped early: {m['fault']}")


if __name__ == "__main__":
    main()
