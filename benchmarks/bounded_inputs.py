"""What the bounds on reads and moves cost: a gzip bomb in a run, a crawling go to or jog, a
feed slider dragged for ten minutes.

Run: ``PYTHONPATH=. python benchmarks/bounded_inputs.py [--gigabytes 4]`` (a few seconds).

- ``load_run`` of a 2,001-sample rig run whose CSV was replaced by a gzip bomb (rows of
  zeros, 64 MB members written again and again): the time to its RecorderError and the
  process's peak resident memory before and after (``ru_maxrss``).
- ``form_plans.go_to`` (Rotate +40°) and ``cartesian_jog.plan_jog`` (x +50 mm) at speeds
  whose move would pass the move limit: the time to the ValueError, beside the time to plan
  the slowest speed that fits.
- ``control.rt.feed.Timeline``: 60,000 override changes 10 ms apart (a slider dragged for ten
  minutes): the entries kept and their final spacing, and what one thinning of a full list
  costs (the controller's tick pays it, a handful of times a move at most).
"""

from __future__ import annotations

import argparse
import gzip
import resource
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control.motion import form_plans
from control.motion.cartesian_jog import plan_jog
from control.recorder import RecorderError, Run, load_run, save_run
from control.rt.feed import MAX_ENTRIES, Timeline
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def timed(call: Callable[[], object]) -> tuple[float, str]:
    """Seconds ``call`` took, and what it said if it raised a ValueError or RecorderError."""
    start = time.perf_counter()
    try:
        call()
        said = "planned"
    except (ValueError, RecorderError) as exc:
        said = str(exc)
    return time.perf_counter() - start, said


def bomb(gigabytes: int) -> None:
    with tempfile.TemporaryDirectory() as data:
        t = np.arange(2001) * 1e-3
        zero = np.zeros((2001, 1))
        files = save_run(Run.from_machine(RIG, "step", "complete", RIG.track, t, zero, zero,
                                          zero), Path(data))
        member = gzip.compress(b"0,0,0,0\n" * ((64 << 20) // 8), compresslevel=9)
        with files.csv.open("wb") as out:
            for _ in range(gigabytes * 16):
                out.write(member)
        before = peak_mb()
        seconds, said = timed(lambda: load_run(files.json))
        print(f"gzip bomb, {gigabytes} GB in {files.csv.stat().st_size / 1e6:.1f} MB: refused in "
              f"{seconds * 1e3:.1f} ms, peak RSS {before:.0f} MB before, {peak_mb():.0f} MB after")
        print(f"  {said.split(': ', 1)[1][:110]}…")


def crawls() -> None:
    middle = np.array([(j.lower + j.upper) / 2 for j in UNIMATE.joints])
    target = middle.copy()
    target[1] += 40.0
    for speed in (0.01, 0.001, 1e-5):
        seconds, said = timed(lambda s=speed: form_plans.go_to(UNIMATE, middle, target, s,
                                                                dt=1e-3))
        print(f"go to Rotate +40° at speed {speed:g}: {seconds * 1e3:.1f} ms, {said[:60]}")
    start = np.array([1500.0, 10.0, 5.0, 20.0, 30.0, 10.0])
    for speed in (0.01, 1e-3, 1e-5):
        seconds, said = timed(lambda s=speed: plan_jog(start, [50, 0, 0, 0, 0, 0], UNIMATE,
                                                       speed=s))
        print(f"Cartesian jog x +50 mm at speed {speed:g}: {seconds * 1e3:.1f} ms, {said[:60]}")


def slider() -> None:
    timeline = Timeline()
    for k in range(60_000):
        timeline.add(round(k * 0.01, 4), 0.3 + 0.6 * (k % 97) / 96)
    print(f"feed slider, 60,000 changes over 600 s: {len(timeline.entries)} kept, "
          f"{timeline.spacing:g} s apart at least")
    costs = []
    for _ in range(200):
        full = Timeline(entries=[(k * 0.06, 0.5) for k in range(MAX_ENTRIES - 1)])
        start = time.perf_counter()
        full.add(MAX_ENTRIES * 0.06, 0.7)
        costs.append(time.perf_counter() - start)
    print(f"  thinning a full list of {MAX_ENTRIES:,}: median {np.median(costs) * 1e6:.0f} µs, "
          f"max {max(costs) * 1e6:.0f} µs of 200")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gigabytes", type=int, default=4, help="the bomb's unpacked size")
    args = parser.parse_args()
    bomb(args.gigabytes)
    crawls()
    slider()


if __name__ == "__main__":
    main()
