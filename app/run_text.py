"""A run in words, as the Runs tab, ``servodesk move`` and ``servodesk runs`` show it."""

from __future__ import annotations

import itertools
from datetime import datetime

from control.motion.moves import Summary, summary_cells, summary_columns
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


def summary_table(summaries: list[tuple[str, Summary]]) -> list[str]:
    """The result table of a move in aligned columns, as the Moves tab shows it
    (``moves.SUMMARY_COLUMNS`` by the kind of result): one table per kind, in the order the
    rows come, a blank line between."""
    if not summaries:
        return ["no joint moved: nothing to summarise"]
    lines: list[str] = []
    for _, group in itertools.groupby(summaries, key=lambda row: row[1].METRIC):
        rows = list(group)
        cells = [summary_columns(rows), *(summary_cells(label, s) for label, s in rows)]
        widths = [max(len(row[c]) for row in cells) for c in range(len(cells[0]))]
        lines.extend([*([""] if lines else []),
                      *("  ".join(cell.ljust(w) if c == 0 else cell.rjust(w)
                                  for c, (cell, w) in enumerate(zip(row, widths, strict=True)))
                        .rstrip() for row in cells)])
    return lines
