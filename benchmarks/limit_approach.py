"""Jogging up to a soft limit: where the target and the arm come to rest, and what trips.

Run: ``PYTHONPATH=. python benchmarks/limit_approach.py`` (about 15 s; the simulated
Unimate 2000B in real time).

Up/Down (limits −27…30°, goal tolerance 0.5°) is jogged from 27° toward its upper limit two
ways: position-jog steps of 1° (the issue's Up/Down presses; the last one asks for 31°),
each waited out; and a velocity jog streamed at 50 Hz at 100°/s (capped at its jog speed,
6.25°/s) for 2 s. For each the script prints where the hold target stopped, the highest
reading seen, where the arm rests a second later and how far inside the limit, and any
fault or E-stop (issue 25: the steps latched "feedback fault … frozen encoder").
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient
from hw.machine import load_machine

MACHINE = load_machine("unimate2000b")
UPDOWN = 2
JOINT = MACHINE.joints[UPDOWN]


def watch(client: ControlClient, seconds: float, act=None) -> float:
    """The highest Up/Down reading over ``seconds``, calling ``act`` every 20 ms."""
    highest = -float("inf")
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if act is not None:
            act()
        highest = max(highest, client.status().position[UPDOWN])
        time.sleep(0.02 if act is not None else 0.002)
    return highest


def to_27(client: ControlClient) -> None:
    client.jog_position(UPDOWN, 27.0 - client.status().desired[UPDOWN])
    while abs(client.status().position[UPDOWN] - 27.0) > JOINT.tolerance:
        time.sleep(0.01)
    watch(client, 0.5)


def report(name: str, client: ControlClient, highest: float) -> None:
    highest = max(highest, watch(client, 1.0))
    status = client.status()
    faults = [e.message for e in client.poll_events() if e.kind in ("fault", "estop")]
    print(f"{name:>22}: target {status.desired[UPDOWN]:.3f}°, highest reading {highest:.3f}°, "
          f"at rest {status.position[UPDOWN]:.3f}° ({JOINT.upper - status.position[UPDOWN]:.3f}° "
          f"inside {JOINT.upper:g}°), E-stop {'LATCHED' if status.estop else 'no'}; "
          f"faults: {faults or 'none'}")


def main() -> None:
    with tempfile.TemporaryDirectory() as data, ControlClient(MACHINE, data_dir=data) as client:
        to_27(client)
        client.poll_events()
        highest = -float("inf")
        for _ in range(4):
            client.jog_position(UPDOWN, 1.0)
            highest = max(highest, watch(client, 1.0))
        report("1° steps from 27°", client, highest)
        to_27(client)
        client.poll_events()
        command = [0.0] * MACHINE.n_joints
        command[UPDOWN] = 100.0
        highest = watch(client, 2.0, lambda: client.jog_velocity(command))
        report("velocity jog held", client, highest)


if __name__ == "__main__":
    main()
