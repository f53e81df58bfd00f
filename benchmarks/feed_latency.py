"""Feed override change → speed change, per kind of move, on the real control process.

Run: ``PYTHONPATH=. python benchmarks/feed_latency.py`` (about a minute; the simulated
Unimate 2000B in real time, as the operator gets it).

For each kind of move (a bare path, a ramp, a sine, a go to, a Positions go at speed 0.1,
an approach in front of a ramp, via points, a Cartesian path, a Cartesian jog) the script
starts the move, and once it is well under way sets the feed override to 50 %, then back to
100 %. For each change it prints, from the moment the client sent it (the status's
``wall_ns`` is the same monotonic clock): when the controller took it (the status shows the
new override), when the path's rate began to change and when it reached the new override
(the rate ramps within every joint's max_accel), and the rate the path then advanced at,
measured from the rows the controller recorded per tick over the next 50 ms. The rate a
path advances at is its speed scale: at 0.5 each joint moves at half its path speed.
A last line gives the issue's case: a 4 s Rotate ramp with the
override dropped to 50 % one second in must reach its end after about 7 s.
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient, Mode
from control.client import MoveHandle
from control.motion import form_plans, moves
from control.motion.robot_model import unimate_model
from hw.machine import load_machine

MACHINE = load_machine("unimate2000b")
ROTATE, INOUT, UPDOWN = 1, 0, 2
UNDER_WAY_S = 0.8  # controller seconds into the path before the override changes
RATE_WINDOW_TICKS = 50
Start = Callable[[ControlClient, np.ndarray], MoveHandle]


def moved(here: np.ndarray, **change: float) -> np.ndarray:
    q = here.copy()
    for key, delta in change.items():
        q[MACHINE.joint_index(key)] += delta
    return q


KINDS: dict[str, Start] = {
    "path": lambda c, q: c.move(moves.ramp(q, moved(q, rotate=40.0), 3.0, machine=MACHINE)),
    "ramp": lambda c, q: c.run(form_plans.ramp(MACHINE, q, ROTATE, q[ROTATE] - 40.0, 3.0,
                                               dt=c.dt)),
    "sine": lambda c, q: c.run(form_plans.sine(MACHINE, q, ROTATE, q[ROTATE] + 30.0, 3.0,
                                               4.0, dt=c.dt)),
    "go_to": lambda c, q: c.go_to(moved(q, rotate=-30.0, updown=5.0), 0.5),
    "positions go 0.1": lambda c, q: c.go_to(moved(q, inout=150.0), 0.1),
    "approach": lambda c, q: c.run(form_plans.ramp(MACHINE, q, ROTATE, q[ROTATE] + 20.0, 2.0,
                                                   start=q[ROTATE] - 40.0, dt=c.dt)),
    "via_points": lambda c, q: c.run(form_plans.via_points(
        MACHINE, q, np.array([moved(q, rotate=20.0), moved(q, rotate=-10.0, updown=4.0)]),
        0.5, False, dt=c.dt)),
    "cartesian": lambda c, q: c.run(form_plans.via_points(
        MACHINE, q, _tool(q) + np.array([[0.0, 60.0, -60.0], [0.0, 0.0, -120.0]]), 0.25, True,
        dt=c.dt)),
    "cartesian_jog": lambda c, q: c.jog_cartesian([0.0, 0.0, -100.0, 0.0, 0.0, 0.0],
                                                  speed=0.5),
}


def _tool(q: np.ndarray) -> np.ndarray:
    return unimate_model(MACHINE).forward(q)[:3, 3]


def change(client: ControlClient, value: float) -> tuple[float, float, float, float]:
    """Set the override to ``value``; ms from sending to taken, to the rate's first change and
    to the rate at ``value``, and the rate measured from the rows recorded after."""
    before = client.status().feed_rate
    sent = time.monotonic_ns()
    client.feed_override(value)
    taken = first = reached = float("nan")
    while True:
        status = client.status()
        ms = (status.wall_ns - sent) / 1e6
        if taken != taken and status.feed_override == value:
            taken = ms
        if first != first and status.feed_rate != before:
            first = ms
        if abs(status.feed_rate - value) < 1e-9:
            reached = ms
            break
        if not status.moving or ms > 5_000:
            break
        time.sleep(0.0002)
    start = client.status()
    while (status := client.status()).tick - start.tick < RATE_WINDOW_TICKS and status.moving:
        time.sleep(0.001)
    rate = (status.move_done - start.move_done) / max(status.tick - start.tick, 1)
    return taken, first, reached, rate


def under_way(client: ControlClient, handle: MoveHandle, seconds: float) -> None:
    deadline = time.monotonic() + 30.0
    while client.status().move_id != handle.move_id or client.status().mode != Mode.FOLLOW_TRACK:
        assert time.monotonic() < deadline, "the move did not start"
        time.sleep(0.001)
    start = client.status().time_s
    while client.status().time_s - start < seconds:
        time.sleep(0.001)


def main() -> None:
    print(f"{'move':>18} {'change':>9} {'taken ms':>9} {'rate moves ms':>14} "
          f"{'at override ms':>15} {'rows/tick after':>16}")
    with tempfile.TemporaryDirectory() as data, ControlClient(MACHINE, data_dir=data) as client:
        for name, start in KINDS.items():
            client.feed_override(1.0)
            here = np.array(client.status().position)
            handle = start(client, here)
            under_way(client, handle, UNDER_WAY_S)
            for value in (0.5, 1.0):
                taken, first, reached, rate = change(client, value)
                print(f"{name:>18} {'→ ' + format(value, '.0%'):>9} {taken:9.1f} {first:14.1f} "
                      f"{reached:15.1f} {rate:16.2f}")
                time.sleep(0.3)
            result = client.wait(handle, timeout=120)
            assert result.status, result.status
        here = np.array(client.status().position)
        end = here[ROTATE] + 40.0
        handle = client.run(form_plans.ramp(MACHINE, here, ROTATE, end, 4.0, dt=client.dt))
        under_way(client, handle, 1.0)
        client.feed_override(0.5)
        result = client.wait(handle, timeout=120)
        client.feed_override(1.0)
        run = result.run
        arrived = run.t[np.flatnonzero(np.abs(run.desired[:, ROTATE] - end) < 1e-9)[0]]
        print(f"4 s Rotate ramp, override 50 % from 1 s: the ramp reached its end after "
              f"{arrived:.2f} s (7 s expected; 4 s at 100 %)")

if __name__ == "__main__":
    main()
