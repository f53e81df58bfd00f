"""A run in words, as the Runs tab, ``servodesk move`` and ``servodesk runs`` show it."""

from __future__ import annotations

import math
from dataclasses import asdict
from datetime import datetime
from typing import Any

from control.motion.moves import SUMMARY_COLUMNS, StepSummary, summary_cells
from control.recorder import Run

META_SHOWN = ("joint", "target", "targets", "ramp_time", "period", "duration", "file", "duty",
              "pose")


def local_time(iso: str) -> str:
    """An ISO 8601 time in the local zone, to the second (``?`` for none)."""
    try:
        return datetime.fromisoformat(iso).astimezone().strftime("%Y-%m-%d %H:%M:%S")
    except ValueError:
        return iso or "?"


def run_lines(run: Run, name: str) -> list[str]:
    """Its name, machine, kind and status, start, samples, backend and the move's fields."""
    meta = run.meta
    lines = [f"{name}", f"{run.machine} · {run.kind} · {run.status}",
             f"started {local_time(run.start_time)} · {run.samples} samples at "
             f"{run.sample_time_s * 1e3:g} ms"]
    if "backend" in meta:
        lines.append(f"backend {meta['backend']}")
    lines.extend(f"{key}: {meta[key]}" for key in META_SHOWN if key in meta)
    return lines


def summary_table(summaries: list[tuple[str, StepSummary]]) -> list[str]:
    """The result table of a move (``moves.SUMMARY_COLUMNS``), in aligned columns."""
    if not summaries:
        return ["no joint moved: nothing to summarise"]
    rows = [SUMMARY_COLUMNS, *(summary_cells(label, s) for label, s in summaries)]
    widths = [max(len(row[c]) for row in rows) for c in range(len(SUMMARY_COLUMNS))]
    return ["  ".join(cell.ljust(w) if c == 0 else cell.rjust(w)
                      for c, (cell, w) in enumerate(zip(row, widths, strict=True))).rstrip()
            for row in rows]


def summary_records(summaries: list[tuple[str, StepSummary]]) -> list[dict[str, Any]]:
    """The result metrics as JSON-ready records (a NaN or a time never reached: null)."""
    return [{"label": label, **{k: _plain(v) for k, v in asdict(s).items()}}
            for label, s in summaries]


def _plain(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return list(value) if isinstance(value, tuple) else value
