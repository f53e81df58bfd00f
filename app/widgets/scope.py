"""A live plot widget drawn with the braille raster: a title row, y labels, the traces and
a time axis (``app.plotting.strips.plot_strips``). ``plot`` replaces what is shown and repaints
only the rows that changed; nothing is computed while the widget is hidden."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.geometry import Region, Size
from textual.strip import Strip
from textual.widget import Widget

from app.plotting.braille import Rows, Trace
from app.plotting.strips import plot_strips


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
        self._rows = Rows()  # the traces' rows as last drawn: a frame makes the changed ones
        self.repaints = 0  # frames that changed what it shows (tests of the idle cost)

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
        before = self._lines
        self._draw()
        changed = [y for y, (old, new) in enumerate(zip(before, self._lines, strict=False))
                   if old != new]
        if len(before) != len(self._lines):
            self.refresh()
        elif changed:  # a plot at rest draws the same rows: only the rows that moved repaint
            width = self.size.width
            self.refresh(*(Region(0, y, width, 1) for y in changed))
        self.repaints += bool(changed) or len(before) != len(self._lines)

    def on_resize(self) -> None:
        self._draw()

    def _draw(self) -> None:
        self._drawn_for = self.size
        self._lines = plot_strips(self._traces, self._x_range, self._y_range, self._title,
                                  self.size.width, self.size.height, self.app.console,
                                  zero_line=self._zero_line, x_labels=self._x_labels,
                                  drawn=self._rows)

    def render_line(self, y: int) -> Strip:
        if self.size != self._drawn_for:
            self._draw()
        if y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)

