"""Moves that end in position (issue 24): how long each move settles after its path, and what
judging it costs the control loop.

Run: ``PYTHONPATH=. python benchmarks/in_position.py [--seed 0] [--sets HOLD,TRACK]`` (about
20 s; the lockstep simulated Unimate 2000B with the controller's start sets,
``control.rt.law.start_sets``, or the machine file's sets named, e.g. ``thesis_hold,thesis_track``,
the sets the issue's operator had).

For each speed fraction the robot goes from the middle of every joint's range to home, to
park, and makes the operator's move of issue 24 (In/Out +50 mm, Bend +10°); for each move
the script prints how it ended (``complete`` or ``unsettled: …``), the path's duration, the
settle after it (controller s from the path's end to the move's end: at least two 100 ms
windows), the joint that came in position last and when, and the largest error from the
goal when it ended. Then the cost of one ``GoalCheck.sample`` (a sample of the settle, six
joints), median of 20,000 calls, which the loop pays every sample of a settle.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient
from control.rt.settle import GoalCheck
from hw.machine import Machine, load_machine

SPEEDS = (0.25, 0.5, 1.0)
CALLS = 20_000


def moves_of(machine: Machine) -> list[tuple[str, np.ndarray | None]]:
    """The moves, each from where the one before ended (None: the operator's, relative)."""
    return [("middle → home", np.array(machine.home)), ("home → park", np.array(machine.park)),
            ("In/Out +50, Bend +10", None)]


def settle_row(label: str, speed: float, result, machine: Machine) -> str:
    settle = result.settle
    times = [np.inf if t is None else t for t in settle.get("settle_s", [])]
    last = int(np.argmax(times)) if times else 0
    ended = result.run.t[-1] - settle.get("path_end_s", result.run.t[-1])
    error = max((abs(e) / j.goal_tolerance for e, j in
                 zip(settle.get("goal_error", []), machine.joints, strict=True)), default=0.0)
    path_s = result.plan.samples * result.run.sample_time_s
    status = result.status if len(result.status) < 40 else result.status[:37] + "…"
    return (f"{speed:>6.2f} {label:>22} {status:>40} {path_s:>7.2f} {ended:>9.3f} "
            f"{machine.joints[last].name:>8} {times[last] if times else np.nan:>8.3f} "
            f"{error:>12.2f}")


def sample_cost_us(machine: Machine) -> float:
    goal = [(j.lower + j.upper) / 2 for j in machine.joints]
    check = GoalCheck(machine, goal, 0, machine.sample_time_s)
    check.goal_time_s = float("inf")  # never a verdict: every call judges every joint
    position = list(goal)
    costs = []
    for k in range(CALLS):
        position[0] = goal[0] + (k % 3) * 0.2617  # a count of dither
        before = time.perf_counter_ns()
        check.sample(k * 1_000_000, position)
        costs.append(time.perf_counter_ns() - before)
    return statistics.median(costs) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sets", default="", help="HOLD,TRACK: the machine file's sets to use")
    args = parser.parse_args()
    machine = load_machine("unimate2000b")
    middle = np.array([(j.lower + j.upper) / 2 for j in machine.joints])
    print(f"{'speed':>6} {'move':>22} {'ended':>40} {'path s':>7} {'settle s':>9} "
          f"{'last in':>8} {'at s':>8} {'end error/goal':>12}")
    with tempfile.TemporaryDirectory() as data, \
            ControlClient(machine, "sim", lockstep=True, seed=args.seed, data_dir=data) as client:
        if args.sets:
            for which, name in zip(("hold", "track"), args.sets.split(","), strict=True):
                client.set_coefficients(which, machine.coefficients[name],
                                        override=f"benchmark: the {name} set")
        for speed in SPEEDS:
            client.wait(client.go_to(middle, 0.5))
            for label, target in moves_of(machine):
                if target is None:
                    target = np.array(client.status().desired)
                    target[0] += 50.0
                    target[3] += 10.0
                result = client.wait(client.go_to(target, speed))
                print(settle_row(label, speed, result, machine))
    print(f"GoalCheck.sample, six joints: {sample_cost_us(machine):.1f} µs a call "
          f"(median of {CALLS:,})")


if __name__ == "__main__":
    main()
