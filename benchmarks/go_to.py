"""Going to home and park: how long a go-to takes and how the joints arrive, by speed fraction.

Run: ``PYTHONPATH=. python benchmarks/go_to.py [--seed 0]`` (about 20 s on a busy two-core
machine; the lockstep simulated Unimate 2000B with the machine file's hold and track sets).

For each speed fraction the robot goes from the middle of every joint's range (where the
simulator powers up) to home (Yaw turns 87.5°), then to park (``ControlClient.go_to``, the
Positions tab's move); for each move the script prints the path's duration, the largest
|actual − desired| while it is followed, the largest distance from the target when the path
ends, and the controller time from the path's end until every joint has stayed within its
``tolerance`` of the target for 0.5 s (the Positions tab's "at" is now the controller's
settle, ``MoveResult.complete``: ``benchmarks/in_position.py``),
and the largest distance from the target 1 to 4 s after the path (the hold's slow swing).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient
from hw.machine import load_machine

SPEEDS = (0.25, 0.5, 1.0)
SETTLED_S = 0.5  # within tolerance this long is settled (the Positions tab's rule before issue 24)
GIVE_UP_S = 10.0  # controller seconds
SWING_S = (1.0, 4.0)  # after the path, controller seconds


def after_path(client: ControlClient, target: np.ndarray, tolerance: np.ndarray
               ) -> tuple[float, np.ndarray]:
    """From the path's end: the controller seconds until every joint stays within tolerance
    for SETTLED_S (inf if not within GIVE_UP_S), and ``(J,)`` each joint's largest distance
    from ``target`` between SWING_S."""
    start = client.status().time_s
    settled, inside_since = float("inf"), None
    worst = np.zeros(len(target))
    while (now := client.status()).time_s - start < GIVE_UP_S:
        t, off = now.time_s - start, np.abs(np.array(now.position) - target)
        if SWING_S[0] <= t <= SWING_S[1]:
            worst = np.maximum(worst, off)
        if np.any(off > tolerance):
            inside_since = None
        elif inside_since is None:
            inside_since = t
        elif t - inside_since >= SETTLED_S and settled == float("inf"):
            settled = inside_since
        if settled < float("inf") and t > SWING_S[1]:
            break
        time.sleep(0.001)
    return settled, worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    machine = load_machine("unimate2000b")
    middle = np.array([(j.lower + j.upper) / 2 for j in machine.joints])
    tolerance = np.array([j.tolerance for j in machine.joints])
    names = [j.name for j in machine.joints]
    print(f"{'speed':>6} {'move':>14} {'path s':>7} {'max |e| on path':>20} "
          f"{'off target at end':>20} {'settled after s':>16} {'swing 1-4 s after':>20}")
    with tempfile.TemporaryDirectory() as data, \
            ControlClient(machine, "sim", lockstep=True, seed=args.seed, data_dir=data) as client:
        for speed in SPEEDS:
            client.wait(client.go_to(middle, 0.5))
            after_path(client, middle, tolerance)
            for label, target in (("middle → home", machine.home),
                                  ("home → park", machine.park)):
                result = client.wait(client.go_to(target, speed))
                off = np.abs(np.array(client.status().position) - target)
                settled, swung = after_path(client, np.array(target), tolerance)
                error = np.abs(result.run.actual - result.run.desired).max(axis=0)
                worst, far = int(np.argmax(error / tolerance)), int(np.argmax(off / tolerance))
                most = int(np.argmax(swung / tolerance))
                print(f"{speed:6.2f} {label:>14} {result.run.t[-1]:7.2f} "
                      f"{error[worst]:8.2f} ({names[worst]:>7}) "
                      f"{off[far]:8.2f} ({names[far]:>7}) {settled:16.3f} "
                      f"{swung[most]:8.2f} ({names[most]:>7})   {result.status}")


if __name__ == "__main__":
    main()
