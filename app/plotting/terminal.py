"""A run's response as terminal text, drawn with plotext: one panel per joint that moved, its
desired and actual position on the left axis and its duty on the right, the E-stop, a fault
and the controller's stalls as vertical lines; sized to the terminal. ``servodesk move
--plot`` prints it after the move and ``servodesk runs show --plot`` for a saved run, so an
operator over SSH sees the step response without the TUI.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import TextIO

import numpy as np

from app.plotting.figure import decimate, nice_ticks, tick_text
from app.plotting.run_plot import FLAT_COUNTS, marks, overview
from control.recorder import Run

MIN_ROWS = 12  # lines a joint's panel needs to show a step response, title and axes included
MIN_COLS = 60  # columns a panel needs beside another
# each line's colour and marker: told apart by the marker too, for a terminal without colour
STYLES = {"desired": ("red", "·"), "actual": ("blue", "braille"), "": ("green", "dot")}
KEY = "· desired  ⣀ actual  • duty % (right)"  # in the title: a legend inside would hide the step
MARK_COLORS = {"estop": "red+", "fault": "orange", "stall": "gray"}


@dataclass(frozen=True)
class Layout:
    """Panels in ``rows`` × ``columns``, the whole ``width`` × ``height`` characters."""

    rows: int
    columns: int
    width: int
    height: int


def moved(run: Run) -> list[int]:
    """The joints whose desired position changed, or whose reading moved more than
    ``FLAT_COUNTS`` encoder counts (something moved it)."""
    if not run.samples:
        return []
    counts = np.asarray(run.joint_resolution or (0.0,) * len(run.joint_names))
    desired = np.ptp(run.desired, axis=0) > 1e-9 * np.maximum(1.0, np.abs(run.desired[0]))
    actual = np.ptp(run.actual, axis=0) > FLAT_COUNTS * counts
    return [j for j in range(len(run.joint_names)) if desired[j] or actual[j]]


def layout(panels: int, width: int, height: int) -> Layout:
    """One column while each panel keeps ``MIN_ROWS`` lines, else two if both are
    ``MIN_COLS`` wide; the height grows past the terminal's rather than squash a panel."""
    columns = 2 if (panels > 1 and height // panels < MIN_ROWS
                    and width >= 2 * MIN_COLS) else 1
    rows = -(-panels // columns)
    return Layout(rows, columns, width, max(height, rows * MIN_ROWS))


def response_text(run: Run, width: int, height: int, color: bool) -> str:
    """The plot of the joints that moved in ``width`` × ``height`` characters (taller if
    they need it), then a line for each mark and one naming the joints left out."""
    import plotext as plt

    joints = moved(run)
    notes = [f"{m.label} at {m.t:.3f} s" for m in marks(run)]
    still = [run.joint_names[j] for j in range(len(run.joint_names)) if j not in joints]
    if still and joints:
        notes.append(f"not drawn, did not move: {', '.join(still)}")
    if not joints:
        return "\n".join(["no joint moved: nothing to plot", *notes]) + "\n"
    shape = layout(len(joints), width, max(MIN_ROWS, height - len(notes) - 1))
    plt.main()  # plotext keeps one global figure: start from its whole, not a panel of it
    plt.clf()
    plt.limitsize(False, False)
    plt.subplots(shape.rows, shape.columns)
    plt.plotsize(shape.width, shape.height)
    for k, j in enumerate(joints):
        plt.subplot(k // shape.columns + 1, k % shape.columns + 1)
        _panel(plt, run, j, shape.width // shape.columns, shape.height // shape.rows)
    text = plt.build()
    plt.main()
    plt.clf()
    if not color:
        text = plt.uncolorize(text)
    return "\n".join([text.rstrip("\n"), *notes]) + "\n"


def _panel(plt: ModuleType, run: Run, j: int, width: int, height: int) -> None:
    """Joint ``j``'s panel in ``width`` × ``height`` characters: the plotsix.m panels of the
    SVG export (``run_plot.overview``), its position on the left axis and its duty on the
    right, on the same spans, round ticks and marks."""
    position, duty = overview(run, [j]).panels
    plt.theme("clear")  # the terminal's own background, dark or light
    plt.title(f"{position.title} ({position.unit})   {KEY}")
    for panel, side in ((position, "left"), (duty, "right")):
        for line in panel.lines:
            t, y = decimate(line.x, line.y, 2 * width)
            color, marker = STYLES[line.label]
            plt.plot(t.tolist(), y.tolist(), color=color, yside=side, marker=marker)
        y0, y1 = panel.y_range()
        plt.ylim(y0, y1, yside=side)
        # a space after the right axis's labels keeps them off the next panel's
        _ticks(plt.yticks, y0, y1, max(3, height // 4), " " if side == "right" else "",
               yside=side)
    x0, x1 = position.x_range()
    plt.xlim(x0, x1)
    _ticks(plt.xticks, x0, x1, max(3, width // 12))
    for mark in position.marks:
        plt.vline(mark.t, MARK_COLORS.get(mark.kind, "gray"))
    plt.xlabel("time (s)")
    plt.ylabel(position.unit)
    plt.ylabel("duty (%) ", yside="right")


def _ticks(set_ticks: Callable[..., None], lo: float, hi: float, most: int, after: str = "",
           **side: str) -> None:
    """Round ticks from ``lo`` to ``hi`` (as the SVG's), labelled with the decimals they need."""
    ticks = nice_ticks(lo, hi, most)
    step = ticks[1] - ticks[0] if len(ticks) > 1 else 1.0
    set_ticks(ticks, [tick_text(v, step) + after for v in ticks], **side)


def terminal_size(out: TextIO) -> os.terminal_size:
    """COLUMNS × LINES when set, else the terminal's of stdout, else of ``out`` (stderr, when
    stdout is a file), else 80 × 24."""
    try:
        fallback = os.get_terminal_size(out.fileno())
    except (OSError, ValueError):  # not a terminal, or no file at all
        fallback = os.terminal_size((80, 24))
    return shutil.get_terminal_size(fallback)


def print_response(run: Run, out: TextIO) -> None:
    """The response plot of ``run`` on ``out``, sized to the terminal; coloured only on a
    terminal and without ``NO_COLOR`` (https://no-color.org)."""
    size = terminal_size(out)
    color = out.isatty() and not os.environ.get("NO_COLOR")
    out.write(response_text(run, size.columns, size.lines, color))
    out.flush()
