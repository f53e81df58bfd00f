"""A live plot widget drawn with the braille raster: a title row, y labels, the traces and
a time axis. ``plot`` replaces what is shown; nothing is computed while the widget is hidden.
``plot_strips`` is that drawing on its own (the figure plot draws its panels with it)."""

from __future__ import annotations

from collections.abc import Sequence

from rich.console import Console
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.geometry import Size
from textual.strip import Strip
from textual.widget import Widget

from app.plotting.braille import Trace, render

LABEL_WIDTH = 8
AXIS_STYLE = Style(dim=True)


def tick_label(value: float, span: float) -> str:
    """A y label short enough for the margin, with as many decimals as the span needs."""
    digits = 0 if span >= 50 else 1 if span >= 5 else 2 if span >= 0.5 else 3
    return f"{value:.{digits}f}"


class ScopePlot(Widget):
    """Traces over ``x_range`` (s) and ``y_range``; the newest data on the right."""

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._traces: Sequence[Trace] = ()
        self._x_range = (0.0, 1.0)
        self._y_range = (0.0, 1.0)
        self._title = Text()
        self._zero_line = False
        self._x_labels = ("", "", "")
        self._lines: list[Strip] = []
        self._drawn_for = Size(0, 0)

    def plot(self, traces: Sequence[Trace], x_range: tuple[float, float],
             y_range: tuple[float, float], title: Text, *, zero_line: bool = False,
             x_labels: tuple[str, str, str] | None = None) -> None:
        """Show ``traces`` (later ones on top); ``x_labels`` left, middle, right of the axis."""
        self._traces = traces
        self._x_range = x_range
        self._y_range = y_range
        self._title = title
        self._zero_line = zero_line
        self._x_labels = x_labels or (f"{x_range[0]:g}", "", f"{x_range[1]:g}")
        self._draw()
        self.refresh()

    def on_resize(self) -> None:
        self._draw()

    def _draw(self) -> None:
        self._drawn_for = self.size
        self._lines = plot_strips(self._traces, self._x_range, self._y_range, self._title,
                                  self.size.width, self.size.height, self.app.console,
                                  zero_line=self._zero_line, x_labels=self._x_labels)

    def render_line(self, y: int) -> Strip:
        if self.size != self._drawn_for:
            self._draw()
        if y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)


def plot_strips(traces: Sequence[Trace], x_range: tuple[float, float],
                y_range: tuple[float, float], title: Text, width: int, height: int,
                console: Console, *, zero_line: bool = False,
                x_labels: tuple[str, str, str] = ("", "", "")) -> list[Strip]:
    """``height`` strips of ``width`` cells: a title row, y labels and the traces, the time
    axis (blank strips when there is no room for a plot)."""
    if width <= LABEL_WIDTH + 2 or height < 3:
        return [Strip.blank(width) for _ in range(height)]
    cols, rows = width - LABEL_WIDTH - 1, height - 2
    body = render(traces, x_range, y_range, cols, rows, guide=AXIS_STYLE,
                  guide_y=0.0 if zero_line else None)
    labels = _y_labels(y_range, rows)
    lines = [Strip(list(title.render(console))).crop(0, width).adjust_cell_length(width)]
    for r, strip in enumerate(body):
        margin = Segment(labels[r].rjust(LABEL_WIDTH)[:LABEL_WIDTH] + "┤", AXIS_STYLE)
        lines.append(Strip([margin, *strip], width))
    lines.append(_axis(x_labels, width, cols))
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
