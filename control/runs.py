"""Turning a move segment's record into a ``Run`` for the recorder."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

from control.recorder import Run
from hw.machine import Machine


def start_stamp() -> str:
    """The ISO 8601 UTC time a move starts, as runs carry it."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def run_from_record(machine: Machine, kind: str, status: str, meta: dict, record: np.ndarray,
                    sample_time_s: float) -> Run:
    """Build a run from ``record (N, 1 + 3J)`` rows of t, desired, actual, duty per joint."""
    n = machine.n_joints
    record = np.asarray(record, dtype=np.float64).reshape(-1, 1 + 3 * n)
    extra = {k: v for k, v in meta.items() if k not in ("coefficients", "start_time")}
    return Run(
        machine=machine.name,
        kind=kind,
        status=status,
        start_time=str(meta.get("start_time") or start_stamp()),
        sample_time_s=sample_time_s,
        coefficients=meta.get("coefficients", {}),
        joint_names=tuple(j.name for j in machine.joints),
        joint_units=tuple(j.unit for j in machine.joints),
        t=record[:, 0].copy(),
        desired=record[:, 1:1 + n].copy(),
        actual=record[:, 1 + n:1 + 2 * n].copy(),
        duty=record[:, 1 + 2 * n:].copy(),
        meta=extra,
    )
