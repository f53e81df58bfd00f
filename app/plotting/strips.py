"""Plots drawn as terminal text: a panel (``plot_strips``: a title row, y labels, the braille
traces, a time axis) and a figure's panels in a grid (``figure_strips``), as many columns as
the panels need to keep at least ``MIN_ROWS`` rows of plot each; ``figure_text`` is that
grid as plain text (``servodesk runs export --format txt``). The widgets show these strips
(``app.widgets.scope``, ``app.widgets.figure_plot``); nothing here is a widget."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass

from rich.console import Console
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.geometry import Size
from textual.strip import Strip

from app.plotting.braille import Canvas, Rows, Trace, render_many
from app.plotting.figure import Figure, Panel

LABEL_WIDTH = 8
AXIS_STYLE = Style(dim=True)
MIN_ROWS = 3  # rows of plot a panel needs, besides its title and time axis
MIN_PLOT_COLS = 16  # columns of plot a panel needs, besides its y labels
GAP = 2  # columns between panels side by side


def tick_label(value: float, span: float) -> str:
    """A y label short enough for the margin, with as many decimals as the span needs."""
    digits = 0 if span >= 50 else 1 if span >= 5 else 2 if span >= 0.5 else 3
    return f"{value:.{digits}f}"


@dataclass(frozen=True)
class Plot:
    """One panel of ``plots_strips``: traces over ``x_range`` and ``y_range`` under ``title``
    in ``width × height`` cells, a zero line, the time axis's labels, the ``marks``' vertical
    lines, and ``drawn``: its rows as last drawn (``braille.Rows``)."""

    traces: Sequence[Trace]
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    title: Text
    width: int
    height: int
    zero_line: bool = False
    x_labels: tuple[str, str, str] = ("", "", "")
    marks: Sequence[tuple[float, Style]] = ()
    drawn: Rows | None = None


def plot_strips(traces: Sequence[Trace], x_range: tuple[float, float],
                y_range: tuple[float, float], title: Text, width: int, height: int,
                console: Console, *, zero_line: bool = False,
                x_labels: tuple[str, str, str] = ("", "", ""),
                marks: Sequence[tuple[float, Style]] = (), drawn: Rows | None = None
                ) -> list[Strip]:
    """``height`` strips of ``width`` cells: a title row, y labels and the traces (and the
    ``marks``' vertical lines), the time axis (blank strips when there is no room for a
    plot); ``drawn``: the traces' rows as last drawn (``braille.Rows``), made again only where
    they changed."""
    return plots_strips([Plot(traces, x_range, y_range, title, width, height, zero_line,
                              x_labels, marks, drawn)], console)[0]


def plots_strips(plots: Sequence[Plot], console: Console) -> list[list[Strip]]:
    """``plot_strips`` of each plot, their traces rastered in one pass (``render_many``); a
    plot's title row and time axis made again only when they changed."""
    roomy = [p for p in plots if p.width > LABEL_WIDTH + 2 and p.height >= 3]
    bodies = iter(render_many([Canvas(p.traces, p.x_range, p.y_range, p.width - LABEL_WIDTH - 1,
                                      p.height - 2, AXIS_STYLE, 0.0 if p.zero_line else None,
                                      p.marks, p.drawn) for p in roomy]))
    out = []
    for p in plots:
        if p.width <= LABEL_WIDTH + 2 or p.height < 3:
            out.append([Strip.blank(p.width) for _ in range(p.height)])
            continue
        out.append(_framed(p, next(bodies), console))
    return out


def _framed(p: Plot, body: list[Strip], console: Console) -> list[Strip]:
    """A plot's rows of traces under its title, beside its y labels, over its time axis."""
    width, drawn = p.width, p.drawn
    cols, rows = width - LABEL_WIDTH - 1, p.height - 2
    labels = _y_labels(p.y_range, rows)
    key = (p.title.plain, tuple(p.title.spans), p.title.style, width)
    if drawn is not None and drawn.title is not None and drawn.title[0] == key:
        title = drawn.title[1]
    else:
        title = Strip(list(p.title.render(console))).crop(0, width).adjust_cell_length(width)
        if drawn is not None:
            drawn.title = (key, title)
    lines = [title]
    before = drawn.framed if drawn is not None and len(drawn.framed) == rows else []
    framed = []
    for r, strip in enumerate(body):
        label = labels[r].rjust(LABEL_WIDTH)[:LABEL_WIDTH] + "┤"
        if before and before[r][0] is strip and before[r][1] == label:
            line = before[r][2]  # the same row beside the same label: as drawn
        else:
            line = Strip([Segment(label, AXIS_STYLE), *strip], width)
        framed.append((strip, label, line))
        lines.append(line)
    axis_key = (p.x_labels, width)
    if drawn is not None and drawn.axis is not None and drawn.axis[0] == axis_key:
        axis = drawn.axis[1]
    else:
        axis = _axis(p.x_labels, width, cols)
    if drawn is not None:
        drawn.framed, drawn.axis = framed, (axis_key, axis)
    lines.append(axis)
    return lines


def _y_labels(y_range: tuple[float, float], rows: int) -> list[str]:
    y0, y1 = y_range
    labels = [""] * rows
    span = y1 - y0
    labels[0] = tick_label(y1, span)
    labels[-1] = tick_label(y0, span)
    if rows >= 5:
        labels[rows // 2] = tick_label((y0 + y1) / 2, span)
    return labels


def _axis(x_labels: tuple[str, str, str], width: int, cols: int) -> Strip:
    left, middle, right = x_labels
    axis = [" "] * cols
    for start, label in ((0, left), (max(0, cols // 2 - len(middle) // 2), middle),
                         (max(0, cols - len(right)), right)):
        for i, ch in enumerate(label):
            if start + i < cols:
                axis[start + i] = ch
    text = " " * LABEL_WIDTH + "└" + "".join(axis)
    return Strip([Segment(text[:width], AXIS_STYLE)], width).adjust_cell_length(width)


def panel_size() -> Size:
    """The least room one panel takes."""
    return Size(LABEL_WIDTH + 1 + MIN_PLOT_COLS, MIN_ROWS + 2)


def grid(count: int, columns: int, size: Size) -> tuple[int, int] | None:
    """``(columns, rows)`` of a grid of ``count`` panels that fits ``size`` with every panel
    at least ``panel_size``: the given ``columns``, or (0) the fewest that fit; None if
    none does."""
    least = panel_size()
    choices = [columns] if columns else range(1, count + 1)
    for c in choices:
        rows = math.ceil(count / c)
        if (size.width - GAP * (c - 1)) // c >= least.width and size.height // rows >= least.height:
            return c, rows
    return None


def cells(count: int, columns: int, rows: int, size: Size) -> list[tuple[int, int, int, int]]:
    """``(x, y, width, height)`` of each of ``count`` panels in a ``columns × rows`` grid."""
    width = (size.width - GAP * (columns - 1)) // columns
    height = size.height // rows
    return [((k % columns) * (width + GAP), (k // columns) * height, width, height)
            for k in range(count)]


def figure_strips(figure: Figure, size: Size, console: Console) -> list[Strip]:
    """The figure's panels in their grid filling ``size``, one strip per row; blank if they
    do not fit (``grid``)."""
    lines = [Strip.blank(size.width) for _ in range(size.height)]
    layout = grid(len(figure.panels), figure.columns, size)
    if layout is None:
        return lines
    for panel, (x, y, w, h) in zip(figure.panels, cells(len(figure.panels), *layout, size),
                                   strict=True):
        for row, strip in enumerate(_panel_strips(panel, w, h, console)):
            line = lines[y + row]
            lines[y + row] = Strip.join([line.crop(0, x), strip, line.crop(x + w, size.width)])
    return lines


def figure_text(figure: Figure, width: int = 160, height: int = 48) -> str:
    """The figure as plain text, its title above the panels drawn as on the screen (braille
    dots) at ``width × height``. ValueError if its panels do not fit."""
    size = Size(width, height - 1)
    if grid(len(figure.panels), figure.columns, size) is None:
        raise ValueError(f"{len(figure.panels)} panel(s) do not fit {width}×{height}")
    console = Console(width=width, file=io.StringIO(), color_system=None)
    rows = [strip.text.rstrip() for strip in figure_strips(figure, size, console)]
    return "\n".join([figure.title, *rows]).rstrip() + "\n"


def _panel_strips(panel: Panel, width: int, height: int, console: Console) -> list[Strip]:
    x0, x1 = panel.x_range()
    title = Text(panel.title + (f" ({panel.unit})" if panel.unit else ""), "bold")
    for line in panel.lines:
        if line.label:
            title.append("  ━ ", line.color)
            title.append(line.label)
    for mark in panel.marks:
        title.append("  ┃ ", mark.color)
        title.append(mark.label, mark.color)
    traces = [Trace(line.x, line.y, Style(color=line.color)) for line in panel.lines]
    return plot_strips(traces, (x0, x1), panel.y_range(), title, width, height,
                       console, zero_line=panel.zero_line,
                       x_labels=(f"{x0:.2f}", "", f"{x1:.2f} s"),
                       marks=[(m.t, Style(color=m.color)) for m in panel.marks])
