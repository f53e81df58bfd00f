"""Export time of a run as MCAP (control/run_mcap.py): a 60 s six-joint Unimate run.

    python benchmarks/mcap_export.py [--seconds 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from control.recorder import Run
from control.run_mcap import write_mcap
from hw.machine import load_machine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    machine = load_machine("unimate2000b")
    t = np.arange(round(args.seconds / machine.sample_time_s) + 1) * machine.sample_time_s
    wave = np.sin(t[:, None] * np.arange(1, 7))
    run = Run.from_machine(machine, "path", "complete", machine.track, t, wave * 10.0,
                           wave * 9.9, wave * 50.0, start_time="2026-11-25T00:00:00+00:00")
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            begin = time.perf_counter()
            path = write_mcap(run, Path(tmp) / "run.mcap")
            times.append(time.perf_counter() - begin)
        size = path.stat().st_size
    print(f"MCAP export of a {args.seconds:g} s six-joint run ({len(t)} samples, "
          f"{3 * len(t)} joint messages): best {min(times):.2f} s, median "
          f"{sorted(times)[len(times) // 2]:.2f} s, {size / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
