"""A live plot widget drawn with the braille raster: a title row, y labels, the traces and
a time axis. ``plot`` replaces what is shown; nothing is computed while the widget is hidden."""

from __future__ import annotations

from collections.abc import Sequence

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
        width, height = self.size
        self._drawn_for = self.size
        if width <= LABEL_WIDTH + 2 or height < 3:
            self._lines = [Strip.blank(width) for _ in range(height)]
            return
        cols, rows = width - LABEL_WIDTH - 1, height - 2
        body = render(self._traces, self._x_range, self._y_range, cols, rows,
                      guide=AXIS_STYLE, guide_y=0.0 if self._zero_line else None)
        labels = self._y_labels(rows)
        title = Strip(list(self._title.render(self.app.console)))
        lines = [title.crop(0, width).adjust_cell_length(width)]
        for r, strip in enumerate(body):
            margin = Segment(labels[r].rjust(LABEL_WIDTH)[:LABEL_WIDTH] + "┤", AXIS_STYLE)
            lines.append(Strip([margin, *strip], width))
        lines.append(self._axis(width, cols))
        self._lines = lines

    def _y_labels(self, rows: int) -> list[str]:
        y0, y1 = self._y_range
        labels = [""] * rows
        span = y1 - y0
        labels[0] = tick_label(y1, span)
        labels[-1] = tick_label(y0, span)
        if rows >= 5:
            labels[rows // 2] = tick_label((y0 + y1) / 2, span)
        return labels

    def _axis(self, width: int, cols: int) -> Strip:
        left, middle, right = self._x_labels
        axis = [" "] * cols
        for start, label in ((0, left), (max(0, cols // 2 - len(middle) // 2), middle),
                             (max(0, cols - len(right)), right)):
            for i, ch in enumerate(label):
                if start + i < cols:
                    axis[start + i] = ch
        text = " " * LABEL_WIDTH + "└" + "".join(axis)
        return Strip([Segment(text[:width], AXIS_STYLE)], width).adjust_cell_length(width)

    def render_line(self, y: int) -> Strip:
        if self.size != self._drawn_for:
            self._draw()
        if y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)
