"""How long a client takes to start its controller and to close it (issue 23: the test suite
starts about 600): a lockstep ``ControlClient`` made and closed ``--count`` times in one
process, as a test worker does. The first start includes whatever the process does once (the
fork server's own start, control/launcher.py). Run from a tree as ``PYTHONPATH=. python -m
benchmarks.controller_start`` (as a script, benchmarks/hw.py would hide the hw package)."""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

os.environ.update(SERVODESK_SPIN="0", SERVODESK_WARM_UP="0")  # as the suite's controllers

import control  # after the environment it reads
from control import ControlClient


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=20)
    parser.add_argument("--machine", default="unimate2000b")
    args = parser.parse_args()
    starts, closes = [], []
    with tempfile.TemporaryDirectory() as data:
        for _ in range(args.count):
            began = time.perf_counter()
            client = ControlClient(args.machine, lockstep=True, data_dir=data)
            started = time.perf_counter()
            client.close()
            starts.append(started - began)
            closes.append(time.perf_counter() - started)
    print(f"{args.count} lockstep {args.machine} controllers started and closed in one process "
          f"(the tree of {control.__file__}):")
    print(f"  first start {starts[0] * 1e3:.0f} ms; the others: median start "
          f"{statistics.median(starts[1:]) * 1e3:.1f} ms (max {max(starts[1:]) * 1e3:.1f}), "
          f"median close {statistics.median(closes[1:]) * 1e3:.1f} ms "
          f"(max {max(closes[1:]) * 1e3:.1f})")


if __name__ == "__main__":
    main()
