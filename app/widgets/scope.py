"""A live plot widget drawn with the braille raster: a title row, y labels, the traces and
a time axis (``app.plotting.strips``). ``plot`` replaces what is shown and repaints only the
rows that changed; ``draw_plots`` draws many plots at once, their traces rastered in one
pass (the Scope's twelve, a frame); nothing is computed while the widget is hidden."""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text
from textual.geometry import Region, Size
from textual.strip import Strip

from app.plotting.braille import Rows, Trace
from app.plotting.strips import Plot, plots_strips
from app.widgets.direct_lines import DirectLines


class ScopePlot(DirectLines):
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
        self.set(traces, x_range, y_range, title, zero_line=zero_line, x_labels=x_labels)
        draw_plots([self])

    def set(self, traces: Sequence[Trace], x_range: tuple[float, float],
            y_range: tuple[float, float], title: Text, *, zero_line: bool = False,
            x_labels: tuple[str, str, str] | None = None) -> None:
        """What ``plot`` shows, drawn by the next ``draw_plots`` of this plot."""
        self._traces = traces
        self._x_range = x_range
        self._y_range = y_range
        self._title = title
        self._zero_line = zero_line
        self._x_labels = x_labels or (f"{x_range[0]:g}", "", f"{x_range[1]:g}")

    def on_resize(self) -> None:
        self._draw()

    def _plot(self) -> Plot:
        size = self._drawn_for = self.size
        return Plot(self._traces, self._x_range, self._y_range, self._title, size.width,
                    size.height, self._zero_line, self._x_labels, drawn=self._rows)

    def _draw(self) -> None:
        self._lines = plots_strips([self._plot()], self.app.console)[0]

    def _show(self, lines: list[Strip]) -> None:
        """Show ``lines``, a repaint of the rows that differ from those shown."""
        before, self._lines = self._lines, lines
        changed = [y for y, (old, new) in enumerate(zip(before, lines, strict=False))
                   if old is not new and old != new]
        if len(before) != len(lines):
            self.refresh()
        elif changed:  # a plot at rest draws the same rows: only the rows that moved repaint
            width = self._drawn_for.width
            self.refresh(*(Region(0, y, width, 1) for y in changed))
        self.repaints += bool(changed) or len(before) != len(lines)

    def render_line(self, y: int) -> Strip:
        if self.size != self._drawn_for:
            self._draw()
        if y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)


def draw_plots(plots: Sequence[ScopePlot]) -> None:
    """Draw each of ``plots`` from what it was last ``set`` to, their traces rastered together
    (those over one time axis in one pass of array operations, not a pass a trace)."""
    if not plots:
        return
    drawn = plots_strips([plot._plot() for plot in plots], plots[0].app.console)
    for plot, lines in zip(plots, drawn, strict=True):
        plot._show(lines)
