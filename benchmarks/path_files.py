"""How long a path file past its bound takes to be refused, and the memory it costs.

Writes, in a temporary directory, the file that used to be accepted after most of
a minute and gigabytes of memory (5 million lines, 159 MB, times within 590 s;
issue 12) and times ``read_path`` on it; with ``--inside``, also a file at the
bound (one point per sample of a 600 s move and a header), which still loads.
Peak memory is the process's peak resident set (``ru_maxrss``): the file is
written a few thousand lines at a time, so the peak is the reading's. Prints
figures and asserts nothing::

    python benchmarks/path_files.py [--lines 5000000] [--inside]
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from control.motion.path_files import PathFileError, path_file_bound, read_path
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
HOLD = (1500.0, 0.0, 0.0, 0.0, 0.0, 0.0)
HEADER = "# t\tIn/Out\tRotate\tUp/Down\tBend\tYaw\tSwivel\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=5_000_000,
                        help="lines of the file past the bound (default 5,000,000)")
    parser.add_argument("--seconds", type=float, default=590.0,
                        help="the time its last point is at (default 590 s)")
    parser.add_argument("--inside", action="store_true", help="also load a file at the bound")
    args = parser.parse_args(argv)
    bound = path_file_bound(UNIMATE)
    print(f"bound: {bound.lines:,} lines, {bound.size / 1e6:.1f} MB ({bound.why})")
    print(f"after imports: peak RSS {peak_mb():.0f} MB")
    with tempfile.TemporaryDirectory() as tmp:
        big = write(Path(tmp) / "big.tsv", points(args.lines, args.seconds))
        report("past the bound", big)
        if args.inside:
            inside = points(bound.lines - 1, 600.0)  # and a header line
            report("at the bound", write(Path(tmp) / "inside.tsv", inside, header=HEADER))
    return 0


def points(n: int, last_s: float) -> Iterator[str]:
    """``n`` TSV lines holding the Unimate still, times from 0 to ``last_s``."""
    step = last_s / max(n - 1, 1)
    for k in range(n):
        yield f"{k * step:.10f}\t1500.0\t0\t0\t0\t0\t0\n"


def write(path: Path, lines: Iterator[str], header: str = "") -> Path:
    with path.open("w") as file:
        file.write(header)
        batch: list[str] = []
        for line in lines:
            batch.append(line)
            if len(batch) == 10_000:
                file.write("".join(batch))
                batch.clear()
        file.write("".join(batch))
    return path


def report(label: str, path: Path) -> None:
    start = time.perf_counter()
    try:
        outcome = f"loaded {len(read_path(path, UNIMATE, HOLD).t):,} points"
    except PathFileError as exc:
        outcome = f"refused: {exc}"
    elapsed = time.perf_counter() - start
    print(f"{label}: {path.stat().st_size / 1e6:.1f} MB file; {elapsed:.3f} s; peak RSS "
          f"{peak_mb():.0f} MB; {outcome}")


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


if __name__ == "__main__":
    sys.exit(main())
