"""A ``Figure`` (``app.plotting.figure``) in the terminal: its panels in a grid drawn as
``app.plotting.strips`` draws them. A figure whose panels cannot all get ``MIN_ROWS`` rows
of plot is drawn as its ``compact`` stand-in (one panel, say), and says so rather than
squeezing plots to nothing; ``fits`` tells a caller beforehand."""

from __future__ import annotations

from rich.segment import Segment
from rich.style import Style
from textual.geometry import Size
from textual.strip import Strip
from textual.widget import Widget

from app.plotting.figure import Figure
from app.plotting.strips import cells, figure_strips, grid


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
        return cells(len(figure.panels), *layout, self.size)

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

