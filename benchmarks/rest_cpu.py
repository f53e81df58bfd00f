"""What a real-time controller at rest costs: % of a core, as shipped (spin and warm-up), with
no warm-up (``SERVODESK_WARM_UP=0``), and with neither (``SERVODESK_SPIN=0`` too: the test
suite's controllers but in the modules that test timing, tests/conftest.py ``TIMED``).

Run from the repository root: ``python benchmarks/rest_cpu.py [--seconds 5] [--rounds 2]``.
The three kinds are started by turns, ``rounds`` times, each holding for ``seconds`` after a
one-second start; its CPU time is read from /proc.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from control import ControlClient  # noqa: E402

KINDS = {
    "as shipped": {},
    "no warm-up": {"SERVODESK_WARM_UP": "0"},
    "no spin, no warm-up": {"SERVODESK_WARM_UP": "0", "SERVODESK_SPIN": "0"},
}


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def resting_share(env: dict[str, str], seconds: float, data_dir: Path) -> float:
    """% of a core a Unimate controller uses while it holds, started with ``env``."""
    saved = {name: os.environ.get(name) for name in env}
    os.environ.update(env)
    try:
        client = ControlClient("unimate2000b", data_dir=data_dir)
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    try:
        time.sleep(1.0)
        before, start = cpu_s(client.pid), time.monotonic()
        time.sleep(seconds)
        return 100 * (cpu_s(client.pid) - before) / (time.monotonic() - start)
    finally:
        client.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    shares: dict[str, list[float]] = {kind: [] for kind in KINDS}
    with tempfile.TemporaryDirectory() as data_dir:
        for _ in range(args.rounds):
            for kind, env in KINDS.items():
                shares[kind].append(resting_share(env, args.seconds, Path(data_dir)))
    print(f"a Unimate controller at rest, % of a core (median of {args.rounds}, "
          f"load {os.getloadavg()[0]:.1f}):")
    for kind, values in shares.items():
        print(f"  {kind:<22} {statistics.median(values):5.1f}   "
              f"({', '.join(f'{v:.1f}' for v in values)})")


if __name__ == "__main__":
    main()
