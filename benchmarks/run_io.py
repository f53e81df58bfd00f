"""How long a six-joint run of 10 s, 60 s and 600 s takes to be saved and loaded, and how large
its files are: with today's recorder, and with the recorder of commit 5c3a3f2 side by side
(a %-format and regular expressions per row, gzip at level 9; read from git, no checkout).
Each figure is the median of ``--repeat`` runs. The run is one a controller records: a slow
sine on every joint, actual positions in encoder counts lagging it with noise, duty following
the error. Prints figures and asserts nothing; the old 600 s save takes about a minute::

    python benchmarks/run_io.py [--repeat 3] [--seconds 10 60 600] [--no-old]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from control import recorder  # noqa: E402
from control.motion import moves  # noqa: E402
from hw.machine import load_machine  # noqa: E402

OLD_COMMIT = "5c3a3f2"
UNIMATE = load_machine("unimate2000b")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure (median)")
    parser.add_argument("--seconds", type=float, nargs="+", default=[10.0, 60.0, 600.0])
    parser.add_argument("--no-old", action="store_true", help=f"skip {OLD_COMMIT}'s recorder")
    args = parser.parse_args(argv)
    old = None if args.no_old else old_recorder()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; median of "
          f"{args.repeat}; gzip level {recorder.GZIP_LEVEL} (old: 9)")
    print(f"{'run':>6}  {'save':>8} {'old save':>9}  {'load':>7} {'old load':>9}  "
          f"{'files':>8} {'old files':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for seconds in args.seconds:
            run = recorded_run(round(seconds / UNIMATE.sample_time_s))
            new = measure(recorder, run, Path(tmp) / f"new{seconds:g}", args.repeat)
            was = (measure(old, run, Path(tmp) / f"old{seconds:g}", args.repeat) if old
                   else None)
            then = (f"{was[0]:>8.2f}s", f"{was[1]:>8.2f}s", f"{was[2]:>7.1f}MB") if was else \
                (f"{'-':>9}",) * 3
            print(f"{seconds:>5g}s  {new[0]:>7.2f}s {then[0]}  {new[1]:>6.2f}s {then[1]}  "
                  f"{new[2]:>6.1f}MB {then[2]}")
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


def measure(module: ModuleType, run: recorder.Run, directory: Path, repeat: int
            ) -> tuple[float, float, float]:
    """Median seconds to save ``run`` and to load it back, and its tables' size in MB."""
    saves, loads, files = [], [], None
    for _ in range(repeat):
        files, took = timed(lambda: module.save_run(run, directory))
        saves.append(took)
        loads.append(timed(lambda f=files: module.load_run(f.json))[1])
    assert files is not None
    size = (files.tsv.stat().st_size + files.csv.stat().st_size) / 1e6
    return statistics.median(saves), statistics.median(loads), size


def timed(work: Callable[[], object]) -> tuple[object, float]:
    start = time.perf_counter()
    result = work()
    return result, time.perf_counter() - start


def recorded_run(n: int) -> recorder.Run:
    """``n`` samples of a six-joint move as the controller records one."""
    dt = UNIMATE.sample_time_s
    start = np.array([1508.4405, 0.0055, 1.4968, -0.00488, 2.49876, -0.00895])
    desired = moves.sine(start, start + np.array([100.0, 20.0, 10.0, 30.0, 20.0, 15.0]),
                         period=5.0, duration=n * dt, machine=UNIMATE)[:n]
    counts = np.array(recorder.resolution(UNIMATE))
    rng = np.random.default_rng(2)
    actual = np.round((np.roll(desired, 40, axis=0) + rng.normal(0.0, 0.02, desired.shape))
                      / counts) * counts
    duty = np.clip(np.gradient(desired, dt, axis=0) * 3.0 + 5.0 * (desired - actual)
                   + rng.normal(0.0, 0.5, desired.shape), -100.0, 100.0)
    return recorder.Run.from_machine(UNIMATE, "sine", "complete", UNIMATE.track,
                                     np.arange(n) * dt, desired, actual, duty)


def old_recorder() -> ModuleType:
    """``control/recorder.py`` as it was at ``OLD_COMMIT``, imported as a module of its own."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{OLD_COMMIT}:control/recorder.py"],
                            capture_output=True, text=True, check=True).stdout
    path = Path(tempfile.mkdtemp()) / "old_recorder.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("old_recorder", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


if __name__ == "__main__":
    sys.exit(main())
