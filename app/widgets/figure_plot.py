"""A ``Figure`` (``app.plotting.figure``) in the terminal: its panels in a grid, each drawn
with the braille raster (``plot_strips``), as many columns as the panels need to keep at
least ``MIN_ROWS`` rows of plot each. A figure whose panels cannot all get that much room
is drawn as its ``compact`` stand-in (one panel, say), and says so rather than squeezing
plots to nothing; ``fits`` tells a caller beforehand. ``figure_text`` draws a figure the
same way as plain text (``servodesk runs export --format txt``)."""

from __future__ import annotations

import io
import math

from rich.console import Console
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.geometry import Size
from textual.strip import Strip
from textual.widget import Widget

from app.plotting.braille import Trace
from app.plotting.figure import Figure, Panel
from app.widgets.scope import LABEL_WIDTH, plot_strips

MIN_ROWS = 3  # rows of plot a panel needs, besides its title and time axis
MIN_PLOT_COLS = 16  # columns of plot a panel needs, besides its y labels
GAP = 2  # columns between panels side by side


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


class FigurePlot(Widget):
    """The panels of a figure; ``show`` replaces it. Redrawn only when shown or resized."""

    DEFAULT_CSS = """
    FigurePlot {
        min-height: 5;
    }
    """

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self.figure: Figure | None = None
        self.compact: Figure | None = None
        self.drawn: Figure | None = None  # the one on screen: the figure, or its stand-in
        self._lines: list[Strip] = []
        self._drawn_for = Size(0, 0)

    def show(self, figure: Figure | None, compact: Figure | None = None) -> None:
        """Draw ``figure`` (None: nothing), or ``compact`` when its panels do not fit."""
        self.figure, self.compact = figure, compact
        self._draw()
        self.refresh()

    def fits(self, figure: Figure, size: Size | None = None) -> bool:
        return grid(len(figure.panels), figure.columns, size or self.size) is not None

    def panel_regions(self) -> list[tuple[int, int, int, int]]:
        """``(x, y, width, height)`` of each panel drawn, in the widget (tests, layout)."""
        figure = self.drawn
        if figure is None or not figure.panels:
            return []
        layout = grid(len(figure.panels), figure.columns, self.size)
        if layout is None:
            return []
        return _cells(len(figure.panels), *layout, self.size)

    def on_resize(self) -> None:
        self._draw()

    def _draw(self) -> None:
        size = self._drawn_for = self.size
        blank = [Strip.blank(size.width) for _ in range(size.height)]
        self._lines, self.drawn = blank, None
        figure = self.figure
        if figure is None or not figure.panels or size.width == 0 or size.height == 0:
            return
        if not self.fits(figure) and self.compact is not None and self.fits(self.compact):
            figure = self.compact
        if not self.fits(figure):
            self._lines[0] = Strip([Segment(
                f"enlarge the terminal to plot {len(figure.panels)} panel(s)"[:size.width],
                Style(dim=True))])
            return
        self.drawn = figure
        self._lines = figure_strips(figure, size, self.app.console)

    def render_line(self, y: int) -> Strip:
        if self.size != self._drawn_for:
            self._draw()
        return self._lines[y] if y < len(self._lines) else Strip.blank(self.size.width)


def figure_strips(figure: Figure, size: Size, console: Console) -> list[Strip]:
    """The figure's panels in their grid filling ``size``, one strip per row; blank if they
    do not fit (``grid``)."""
    lines = [Strip.blank(size.width) for _ in range(size.height)]
    layout = grid(len(figure.panels), figure.columns, size)
    if layout is None:
        return lines
    cells = _cells(len(figure.panels), *layout, size)
    for panel, (x, y, w, h) in zip(figure.panels, cells, strict=True):
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


def _cells(count: int, columns: int, rows: int, size: Size) -> list[tuple[int, int, int, int]]:
    width = (size.width - GAP * (columns - 1)) // columns
    height = size.height // rows
    return [((k % columns) * (width + GAP), (k // columns) * height, width, height)
            for k in range(count)]


def _panel_strips(panel: Panel, width: int, height: int, console: Console) -> list[Strip]:
    x0, x1 = panel.x_range()
    title = Text(panel.title + (f" ({panel.unit})" if panel.unit else ""), "bold")
    for line in panel.lines:
        if line.label:
            title.append("  ━ ", line.color)
            title.append(line.label)
    traces = [Trace(line.x, line.y, Style(color=line.color)) for line in panel.lines]
    return plot_strips(traces, (x0, x1), panel.y_range(), title, width, height,
                       console, zero_line=panel.zero_line,
                       x_labels=(f"{x0:.2f}", "", f"{x1:.2f} s"))
