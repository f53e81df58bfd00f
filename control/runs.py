"""A move segment as a run: what the client writes into it for whoever saves it, and the
``Run`` the recorder saves from its record.

Three parties may save a move: the client when the move ends, the controller after its
loop when its client is gone, and the next client to start when both died
(``control/recovery.py``). So the segment carries everything a run needs besides its
record (``segment_meta``): the machine and its joints (name, unit, encoder count and
max_accel, which set the decimals the run is saved with), the kind, the sample time, where
runs go, a run id that tells whether it is already saved, and the metadata of the move.
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from control.recorder import Run, resolution
from control.rt.layout import MoveLayout
from hw.machine import Machine

STANDARD = ("run_id", "machine", "joints", "kind", "sample_time_s", "data_dir", "start_time",
            "coefficients", "controller_pid")  # kept apart from the run's free-form meta


def start_stamp() -> str:
    """The ISO 8601 UTC time a move starts, as runs carry it."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def segment_meta(machine: Machine, kind: str, sample_time_s: float, data_dir: Path,
                 controller_pid: int, meta: dict[str, Any]) -> dict[str, Any]:
    """What a move segment carries so that anyone can save its run (a fresh run id)."""
    return {
        "run_id": uuid.uuid4().hex,
        "machine": machine.name,
        "joints": [[j.name, j.unit, r, j.max_accel]
                   for j, r in zip(machine.joints, resolution(machine), strict=True)],
        "kind": kind,
        "sample_time_s": sample_time_s,
        "data_dir": str(data_dir),
        "controller_pid": controller_pid,
        "start_time": start_stamp(),
        **meta,
    }


def encode_meta(meta: dict[str, Any]) -> bytes:
    return json.dumps(meta, ensure_ascii=False, allow_nan=False, default=str).encode()


def decode_meta(data: bytes) -> dict[str, Any]:
    meta = json.loads(data.decode())
    if not isinstance(meta, dict):
        raise ValueError("the move segment's metadata is not an object")
    return meta


def run_from_segment(buf: memoryview, layout: MoveLayout, meta: dict[str, Any], status: str,
                     timeline: Mapping[str, Sequence[tuple[float, float]]] | None = None) -> Run:
    """The run recorded so far in a move segment (its path's rows, then its settle's);
    ``timeline`` (the controller's ``gaps``, ``feed``, ``pauses``, ``supply``, ``settle`` and
    ``speed_mode``: ``ActiveMove.timeline``) goes into its metadata: ``speed_mode`` as the
    mode the move started in (``reduced`` or ``automatic``), and ``speed_mode_changes``
    ``[t s, mode]`` if it changed during the move."""
    joints = [(str(name), str(unit)) for name, unit, *_ in meta["joints"]]
    resolutions = tuple(float(j[2]) for j in meta["joints"] if len(j) > 2)
    accels = tuple(float(j[3]) for j in meta["joints"] if len(j) > 3)
    n = len(joints)
    record = layout.record(buf)[:layout.recorded(buf)].reshape(-1, 1 + 3 * n).copy()
    extra = {k: v for k, v in meta.items() if k not in STANDARD or k == "run_id"}
    extra["path_samples"] = layout.samples  # the rows of the path; the settle's follow them
    for key, entries in (timeline or {}).items():
        if key == "speed_mode" and entries:  # the controller's, as the move started and changed
            extra[key] = str(entries[0][1])
            if len(entries) > 1:
                extra["speed_mode_changes"] = [list(entry) for entry in entries[1:]]
        elif key == "settle" and entries:  # a record of its own (control/rt/settle.py)
            extra[key] = {k: list(v) if isinstance(v, list | tuple) else v
                          for k, v in dict(entries).items()}
        elif entries:
            extra[key] = [list(entry) for entry in entries]
    return Run(
        machine=str(meta["machine"]),
        kind=str(meta["kind"]),
        status=status,
        start_time=str(meta.get("start_time") or start_stamp()),
        sample_time_s=float(meta["sample_time_s"]),
        coefficients=meta.get("coefficients", {}),
        joint_names=tuple(name for name, _ in joints),
        joint_units=tuple(unit for _, unit in joints),
        t=record[:, 0],
        desired=record[:, 1:1 + n],
        actual=record[:, 1 + n:1 + 2 * n],
        duty=record[:, 1 + 2 * n:],
        meta=extra,
        joint_resolution=resolutions,
        joint_max_accel=accels,
    )
