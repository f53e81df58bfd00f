"""Saving a run the controller finished on its own, its client gone (orphaned)."""

from __future__ import annotations

from pathlib import Path

from control.modes import ActiveMove
from control.recorder import save_run
from control.runs import run_from_record
from hw.machine import Machine


class RunSaver:
    """Writes an orphaned move's record as a run in ``data_dir`` (none: nothing is saved)."""

    def __init__(self, machine: Machine, data_dir: Path | None, dt: float) -> None:
        self.machine = machine
        self.data_dir = data_dir
        self.dt = dt

    def save(self, move: ActiveMove, status: str) -> str:
        """Save ``move`` as recorded so far; return the run's JSON path, or "" if not saved."""
        if self.data_dir is None:
            return ""
        record = move.layout.record(move.segment.buf)[:move.index].copy()
        run = run_from_record(self.machine, move.kind, status, move.meta, record, self.dt)
        try:
            return str(save_run(run, self.data_dir).json)
        except OSError:
            return ""
