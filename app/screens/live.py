"""The tabs' screen, drawn by the rows that changed.

For a partial update (a few numbers changed) Textual's compositor draws every widget whose
parent's area meets the box around all the changes, and every line of each: the screen's 48
lines, the tab bar's 44, each container's 42, to send the terminal the one row of cells that
changed. At 10 updates a second that was most of an idle tab's CPU. Here a widget is drawn
only if it is the front one over some changed cells (a container under its children is not:
the terminal is sent its children's cells), and only over the rows from the first such row
to the last: the terminal is sent the same cells, fewer are drawn.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

from textual._compositor import ChopsUpdate, Compositor
from textual.geometry import Region
from textual.screen import Screen
from textual.strip import Strip
from textual.widget import Widget

NOTHING = Strip([])  # a piece of a line not sent


class ChangedRowsCompositor(Compositor):
    """A compositor whose partial updates draw only the widgets in front over a change, and
    only the rows of them it reaches (full updates are drawn as before)."""

    def __init__(self) -> None:
        super().__init__()
        self._changed: list[Region] | None = None  # while a partial update is drawn
        # the widgets shown, front to back, and on each row: for the widgets shown in _rows_for
        self._rows_for: object = None
        self._front_to_back: list[tuple[Widget, Region, Region]] = []
        self._rows: list[list[tuple[int, int, int]]] = []

    def render_partial_update(self) -> ChopsUpdate | None:
        self._changed = list(self._dirty_regions)
        try:
            return super().render_partial_update()
        finally:
            self._changed = None

    def _render_chops(self, crop: Region, is_rendered_line: Callable[[int], bool]
                      ) -> Sequence[Mapping[int, Strip]]:
        chops = super()._render_chops(crop, is_rendered_line)
        if self._changed:
            # Textual sends a move to the piece of a line that starts where a change ends
            # (and none of its cells): here no widget may have drawn that piece
            for y, _, end in self._regions_to_spans(self._changed):
                line = chops[y]
                if end in line and line[end] is None:
                    line[end] = NOTHING  # type: ignore[index]
        return chops

    def _get_renders(self, crop: Region | None = None
                     ) -> Iterable[tuple[Region, Region, list[Strip]]]:
        changed = self._changed
        if not changed or crop is None:  # a full update: every widget, whole
            yield from super()._get_renders(crop)
            return
        # for each row of changed cells, the widgets on that row front to back: the front one's
        # cells are sent, so a container under its children is drawn only where a change shows
        # it (its padding, a border), most ticks not at all
        rows_of = self._rows_of_widgets()
        reached: dict[int, list[int]] = {}  # a widget's place in front: its first, last row
        for y, x1, x2 in self._regions_to_spans(changed):
            uncovered = [(x1, x2)]
            for place, left, right in rows_of[y] if 0 <= y < len(rows_of) else ():
                if not any(left < end and start < right for start, end in uncovered):
                    continue
                rows = reached.setdefault(place, [y, y])
                rows[1] = y
                uncovered = [piece for start, end in uncovered
                             for piece in ((start, min(end, left)), (max(start, right), end))
                             if piece[0] < piece[1]]
                if not uncovered:
                    break
        widgets = self._front_to_back
        for place in sorted(reached):
            widget, region, clip = widgets[place]
            top, bottom = reached[place]
            shown = region.intersection(clip)
            rows = Region(shown.x, top, shown.width, bottom + 1 - top)
            # the rows as the widget's own clip: the compositor places them where they are
            yield region, clip.intersection(rows), widget.render_lines(
                rows.translate((-region.x, -region.y)))

    def _rows_of_widgets(self) -> list[list[tuple[int, int, int]]]:
        """Each row of the screen's widgets front to back, as (place, first column, end): made
        again only when the widgets shown or where they are changed."""
        visible = self.visible_widgets
        if self._rows_for is not visible:
            self._rows_for = visible
            self._front_to_back = [(w, region, clip) for w, (region, clip) in visible.items()]
            rows: list[list[tuple[int, int, int]]] = [[] for _ in range(self.size.height)]
            for place, (_, region, clip) in enumerate(self._front_to_back):
                x, y, width, height = region.intersection(clip)
                for row in rows[max(0, y):max(0, y + height)]:
                    row.append((place, x, x + width))
            self._rows = rows
        return self._rows


def fits_textual() -> bool:
    """Whether the installed Textual's compositor has the private parts this one builds on
    (``textual>=0.80`` admits releases that may not): else Textual's own draws, whole."""
    try:
        compositor = Compositor()
    except TypeError:
        return False
    return (callable(getattr(Compositor, "_get_renders", None))
            and callable(getattr(Compositor, "render_partial_update", None))
            and isinstance(getattr(compositor, "_dirty_regions", None), set)
            and hasattr(Compositor, "visible_widgets"))


class LiveScreen(Screen):
    """The app's screen of tabs, drawn by ``ChangedRowsCompositor`` where Textual fits it."""

    def __init__(self, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        if fits_textual():
            self._compositor = ChangedRowsCompositor()
