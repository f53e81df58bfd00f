"""The control process keeps to its job: it imports ``control.rt`` (the 1 kHz code), ``hw``,
numpy and the standard library, and nothing else of ours: no client, planning or identification."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

FORBIDDEN = ("scipy", "textual")
OURS = ("control", "hw", "kinematics", "app", "benchmarks")  # top-level packages of this repo


def imported_modules(log: str) -> set[str]:
    """Module names from ``-X importtime`` lines: ``import time: self | cumulative | name``."""
    return {name.strip() for name in
            re.findall(r"^import time:\s+\d+ \|\s+\d+ \|(.+)$", log, re.M)}


def test_the_control_process_imports_no_client_planning_or_identification(tmp_path: Path) -> None:
    """A fresh client process (this one has its fork server already) with every import timed:
    what the fork server imported before it forked the controller, and what the controller
    imported after, as it ran a move, jogs, a set and a hold."""
    script = f"""
import numpy as np
from control import ControlClient, launcher
from control.motion import moves

with ControlClient("unimate2000b", lockstep=True, data_dir={str(tmp_path)!r},
                   heartbeat_timeout_s=3.0) as client:
    start = np.array(client.status().position)
    path = moves.ramp(start, start + np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), 0.2, 0.2,
                      machine=client.machine)
    assert client.wait(client.move(path, kind="ramp"), 60).complete
    client.jog_position(1, 0.5)
    client.jog([0.0] * 6)
    client.set_coefficients("hold", client.machine.hold)
    client.hold()
    print(launcher.server_log() + client.controller_log())
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPROFILEIMPORTTIME": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    modules = imported_modules(done.stdout)
    assert "control.rt.loop" in modules and "hw.sim.plant" in modules, sorted(modules)[:20]
    leaked = sorted(m for m in modules if any(m == f or m.startswith(f"{f}.") for f in FORBIDDEN))
    assert leaked == [], f"the control process imported {leaked}"
    ours = sorted(m for m in modules if m.split(".")[0] in OURS)
    outside = [m for m in ours if not (m == "control" or m.startswith(("control.rt", "hw")))]
    assert outside == [], f"the control process imported {outside}, outside control/rt/ and hw/"


def test_the_move_kinds_are_read_without_numpy() -> None:
    """The controller will check rows against their kind (issue 11): the classification is in
    control.rt.commands, which imports neither numpy nor scipy."""
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys; from control.rt.commands import DUTY_KINDS, "
         "SMOOTH_KINDS, STEP_KINDS; print(sorted(m for m in ('numpy', 'scipy') "
         "if m in sys.modules))"], capture_output=True, text=True, check=True)
    assert loaded.stdout.strip() == "[]"
