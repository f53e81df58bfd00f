"""Holding still on the serial board: false E-stops counted, and resets after watchdog trips.

Run: ``PYTHONPATH=. python benchmarks/serial_hold.py [--seconds 60] [--burners 1]
[--resets 10] [--board-priority normal|fifo] [--machine NAME]``. It starts ``servodesk
emulate --tcp 0`` (the encoders' own wrong readings on: the default glitch scale), a
controller on it, and ``--burners`` busy loops beside; then

1. holds the arm still for ``--seconds`` and counts every E-stop by its cause, resetting
   after each: a feedback fault is a false one (the arm is still and its encoders only
   misread now and then, which the glitch filter must absorb); a link fault is the board
   silent for the 50 ms link timeout (a starved emulator, not the controller's doing);
2. trips the board's watchdog ``--resets`` times (the controller stopped 150 ms) and
   counts the resets after which the arm held where it was, without a fault, for 0.5 s.

``--board-priority normal`` (the default) puts the emulator at normal priority beside the
burners, as ``servodesk emulate`` ran before it took SCHED_FIFO: its answers come late now
and then, the stale-word case; ``fifo`` puts it at SCHED_FIFO 70, as ``servodesk emulate``
and the test suite now do (a board that does not stall). The script sets the priority
itself and uses only what every version of servodesk has, so a checkout of an older commit
measures the same way.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path[:1]:
    sys.path.insert(0, str(ROOT))  # ahead of benchmarks/, whose hw.py would hide the hw package

from control import ControlClient  # noqa: E402
from control.client import Event  # noqa: E402
from hw.machine import load_machine  # noqa: E402

BURN = "while True:\n    pass\n"
TRIP_S = 0.15  # the controller stopped this long: past the board's 50 ms watchdog
HOLD_AFTER_RESET_S = 0.5
WAIT_S = 10.0


def start_emulator(machine: str, priority: str) -> tuple[subprocess.Popen[bytes], str]:
    """``servodesk emulate --tcp 0`` at ``priority``; returns it and the URL it serves."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    child = subprocess.Popen([sys.executable, "-m", "app", "emulate", "--machine", machine,
                              "--tcp", "0"], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.DEVNULL)
    assert child.stdout is not None
    if not select.select([child.stdout], [], [], 60)[0]:
        child.kill()
        raise SystemExit("the emulator did not start within 60 s")
    url = child.stdout.readline().decode().strip()
    if priority == "fifo":
        os.sched_setscheduler(child.pid, os.SCHED_FIFO, os.sched_param(70))
    else:
        os.sched_setscheduler(child.pid, os.SCHED_OTHER, os.sched_param(0))
    return child, url


def cause(reason: str) -> str:
    """An E-stop's cause, in the benchmark's three kinds."""
    if reason.startswith("feedback fault"):
        return "false (feedback)"
    if reason.startswith("link fault"):
        return "link (board silent or its watchdog)"
    return "other"


def latched(event: Event) -> bool:
    return bool(event.payload["latched"])


def released(event: Event) -> bool:
    return not event.payload["latched"]


def reset(client: ControlClient) -> bool:
    """Reset and wait for the release; False if it did not come."""
    client.reset()
    try:
        client.wait_event("estop", WAIT_S, released)
    except TimeoutError:
        return False
    return True


def hold(client: ControlClient, seconds: float) -> Counter[str]:
    """Hold still for ``seconds``; the E-stops on the way by cause, each reset at once."""
    causes: Counter[str] = Counter()
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        try:
            event = client.wait_event("estop", left, latched)
        except TimeoutError:
            break
        reason = str(event.payload["reason"])
        causes[cause(reason)] += 1
        print(f"  {seconds - left:7.1f} s  {reason[:110]}", flush=True)
        if not reset(client):
            causes["reset refused"] += 1
    return causes


def held_for(client: ControlClient, seconds: float) -> bool:
    """Whether the controller runs ``seconds`` of its time from now without latching."""
    since = client.status().time_s
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        status = client.status()
        if status.estop:
            return False
        if status.time_s > since + seconds:
            return True
        time.sleep(0.005)
    return False


def trip_and_reset(client: ControlClient, n: int, tolerance: np.ndarray) -> Counter[str]:
    """Trip the board's watchdog ``n`` times and reset; how each ended."""
    outcomes: Counter[str] = Counter()
    for attempt in range(n):
        if client.status().estop and not reset(client):  # a link fault just before, say
            outcomes["reset not released"] += 1
            continue
        client.poll_events()
        where = np.array(client.status().position)
        os.kill(client.pid, signal.SIGSTOP)
        time.sleep(TRIP_S)
        os.kill(client.pid, signal.SIGCONT)
        try:
            client.wait_event("estop", WAIT_S, latched)
        except TimeoutError:
            outcomes["no trip"] += 1
            continue
        client.poll_events()
        if not reset(client):
            outcomes["reset not released"] += 1
        elif not held_for(client, HOLD_AFTER_RESET_S):
            status = client.status()
            outcomes[f"latched after the release: {cause(status.fault)}"] += 1
            print(f"  reset {attempt + 1}: {status.fault[:110]}", flush=True)
            reset(client)
        elif np.any(np.abs(np.array(client.status().position) - where) > 3 * tolerance):
            outcomes["moved after the release"] += 1
        else:
            outcomes["held"] += 1
    return outcomes


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="holding still (60)")
    parser.add_argument("--burners", type=int, default=1, help="busy loops beside (1)")
    parser.add_argument("--resets", type=int, default=10, help="watchdog trips to reset (10)")
    parser.add_argument("--board-priority", choices=("normal", "fifo"), default="normal")
    parser.add_argument("--machine", default="unimate2000b")
    args = parser.parse_args(argv)
    machine = load_machine(args.machine)
    tolerance = np.array([j.tolerance for j in machine.joints])
    emulator, url = start_emulator(args.machine, args.board_priority)
    burners = [subprocess.Popen([sys.executable, "-c", BURN]) for _ in range(args.burners)]
    try:
        with tempfile.TemporaryDirectory() as data, \
                ControlClient(machine, backend="serial", port=url, data_dir=data,
                              heartbeat_timeout_s=2.0) as client:
            print(f"holding {machine.name} still on {url} (board at {args.board_priority} "
                  f"priority) for {args.seconds:g} s beside {args.burners} burner(s)",
                  flush=True)
            causes = hold(client, args.seconds)
            load = os.getloadavg()[0]
            glitches = client.status().glitches
            outcomes = trip_and_reset(client, args.resets, tolerance)
            reset_load = os.getloadavg()[0]
    finally:
        for burner in burners:
            burner.kill()
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=30)
    print(f"false E-stops (feedback faults holding still): {causes['false (feedback)']} "
          f"in {args.seconds:g} s; link faults: {causes['link (board silent or its watchdog)']}"
          f"; other: {causes['other']}; load average {load:.1f}; glitches rejected per joint "
          f"{list(glitches)}")
    print(f"resets after a watchdog trip that held: {outcomes['held']} of {args.resets}"
          + "".join(f"; {k}: {v}" for k, v in sorted(outcomes.items()) if k != "held")
          + f"; load average {reset_load:.1f}")


if __name__ == "__main__":
    main()
