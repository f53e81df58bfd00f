"""Cost of the eq. 5.1 controller per tick: µs for one update of six joints.

Run: ``python benchmarks/law.py``. The loop calls
``DifferenceLaw.update`` once per joint per 1 ms tick, so this is the share of
the period the control law takes. Errors vary every tick so no branch is
always taken; the best of several repeats is printed (least disturbed by the OS).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control.rt.law import DifferenceLaw, pid
from hw.machine import Coefficients, Machine, load_machine

TICKS = 10_000
REPEATS = 30


def per_six_joint_update_us(machine: Machine, coefficients: Coefficients | None) -> float:
    """Best-of-``REPEATS`` µs for six ``update`` calls (cycling joints on machines with fewer).

    ``coefficients`` None times a call that does nothing: the harness's own floor.
    """
    law = DifferenceLaw(machine, coefficients or machine.hold, machine.sample_time_s)
    update = law.update if coefficients is not None else _nothing
    joints = [j % machine.n_joints for j in range(6)]
    errors = [((k % 200) - 100) * 0.01 for k in range(TICKS)]
    best = float("inf")
    for _ in range(REPEATS):
        law.reset()
        start = time.perf_counter_ns()
        for e in errors:
            for j in joints:
                update(j, e)
        best = min(best, (time.perf_counter_ns() - start) / TICKS / 1e3)
    return best


def _nothing(j: int, error: float) -> float:
    return error


def measure() -> list[tuple[str, float]]:
    """``(case, best µs per six-joint update)`` for each case ``main`` prints."""
    unimate = load_machine("unimate2000b")
    rig = load_machine("rig")
    rig_track = rig.track
    cases = [
        ("unimate2000b hold (P+I, 1 tap)", unimate, unimate.hold),
        ("unimate2000b, rig PID gains on 6 joints (eq. 3.3)", unimate,
         pid(unimate, rig_track.kp[0][0], rig_track.ki[0], rig_track.kd[0])),
        ("rig track PID (eq. 3.3), 1 joint x 6 calls", rig, rig_track),
        ("rig observer (2 w + 2 kp taps), 1 joint x 6 calls", rig, rig.coefficients["observer"]),
        ("floor: six calls of a function that returns its argument", unimate, None),
    ]
    return [(label, per_six_joint_update_us(machine, coefficients))
            for label, machine, coefficients in cases]


def main() -> None:
    print(f"eq. 5.1 law, {TICKS} ticks, best of {REPEATS}: µs per six-joint update")
    for label, us in measure():
        print(f"  {us:6.2f} µs  {label}")


if __name__ == "__main__":
    main()
