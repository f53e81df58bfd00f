"""The control process keeps to its job: it imports no client, planning or identification."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient

FORBIDDEN = ("control.client", "control.motion", "control.identify", "app", "scipy", "textual")


def imported_modules(log: str) -> set[str]:
    """Module names from ``-X importtime`` lines: ``import time: self | cumulative | name``."""
    return {name.strip() for name in
            re.findall(r"^import time:\s+\d+ \|\s+\d+ \|(.+)$", log, re.M)}


def test_the_control_process_imports_no_client_planning_or_identification(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PYTHONPROFILEIMPORTTIME", "1")  # the child inherits it: every import
    with ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path,
                       heartbeat_timeout_s=3.0) as client:
        start = np.array(client.status().position)
        path = np.repeat(start[None, :], 200, axis=0)
        path[:, 2] += np.linspace(0.0, 1.0, 200)
        assert client.wait(client.move(path, kind="ramp"), 60).complete
        client.jog_position(1, 0.5)
        client.jog([0.0] * 6)
        client.set_coefficients("hold", client.machine.hold)
        client.hold()
        modules = imported_modules(client.controller_log())
    assert "control.loop" in modules and "hw.sim.plant" in modules, sorted(modules)[:20]
    leaked = sorted(m for m in modules if any(m == f or m.startswith(f"{f}.") for f in FORBIDDEN))
    assert leaked == [], f"the control process imported {leaked}"
