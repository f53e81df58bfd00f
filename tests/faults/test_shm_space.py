"""Shared memory that fits or refuses: with /dev/shm as small as Docker's default, a move
that does not fit is refused before anything is sent, with both sizes and the fix, and a
move that fits runs; nothing dies of a bus error. The test mounts a 32 MB tmpfs over
/dev/shm in a mount namespace of its own (needs root and util-linux's unshare)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SIZE_MB = 32

SCRIPT = textwrap.dedent("""
    import json, sys
    from control import ControlClient
    from control.motion import moves
    out = {}
    with ControlClient("unimate2000b", lockstep=True, data_dir=sys.argv[1],
                       heartbeat_timeout_s=3.0) as client:
        start = client.status().position
        try:
            client.move(moves.step(start, 1, start[1] + 5.0, duration=600.0,
                                   machine=client.machine), kind="step")
        except OSError as exc:
            out["refused"] = str(exc)
        result = client.wait(client.move(moves.step(start, 1, start[1] + 5.0, duration=3.0,
                                                    machine=client.machine), kind="step"), 60)
        out["short"] = result.status
        out["alive"] = client.alive
    print(json.dumps(out), flush=True)
""")


def test_a_move_too_big_for_dev_shm_is_refused_and_one_that_fits_runs(tmp_path: Path,
                                                                     measured) -> None:
    if os.getuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("mounting a small /dev/shm for the test needs root and unshare")
    command = (f"mount -t tmpfs -o size={SIZE_MB}m tmpfs /dev/shm && "
               f"exec {sys.executable} -c '{SCRIPT}' {tmp_path}")
    done = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", command],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode and "mount" in done.stderr and "permission" in done.stderr.lower():
        pytest.skip(f"this machine will not mount a tmpfs: {done.stderr.strip()}")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["refused"].startswith("a step move of 600.0 s needs "), out
    assert "/dev/shm has" in out["refused"] and "make the move shorter" in out["refused"]
    assert out["short"] == "complete" and out["alive"] is True
    measured("refused_mb", float(out["refused"].split(" needs ")[1].split(" MB")[0]), "MB")
