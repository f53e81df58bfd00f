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

NOTHING = Strip([])  # a piece of a line not sent


class ChangedRowsCompositor(Compositor):
    """A compositor whose partial updates draw only the widgets in front over a change, and
    only the rows of them it reaches (full updates are drawn as before)."""

    def __init__(self) -> None:
        super().__init__()
        self._changed: list[Region] | None = None  # while a partial update is drawn

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
        # the changed cells no widget drawn so far covers: widgets come front to back, and
        # the front one's cells are sent, so a container under its children is drawn only
        # where a change shows it (its padding, a border), most ticks not at all
        uncovered = changed
        for widget, (region, clip) in self.visible_widgets.items():
            if not uncovered:
                return
            shown = region.intersection(clip)
            if not crop.overlaps(shown):  # most widgets: away from every change
                continue
            reached = [shown.intersection(c) for c in uncovered if shown.overlaps(c)]
            if not reached:  # nothing of it is sent: its cells are not in any change
                continue
            uncovered = [piece for c in uncovered for piece in without(c, shown)]
            top = min(r.y for r in reached)
            rows = Region(shown.x, top, shown.width, max(r.bottom for r in reached) - top)
            # the rows as the widget's own clip: the compositor places them where they are
            yield region, clip.intersection(rows), widget.render_lines(
                rows.translate((-region.x, -region.y)))


def without(region: Region, cut: Region) -> list[Region]:
    """What of ``region`` is outside ``cut``: up to four regions (above, below, left, right)."""
    if not region.overlaps(cut):
        return [region]
    x, y, width, height = region
    top, bottom = max(y, cut.y), min(y + height, cut.bottom)
    pieces = [Region(x, y, width, top - y), Region(x, bottom, width, y + height - bottom),
              Region(x, top, cut.x - x, bottom - top),
              Region(cut.right, top, x + width - cut.right, bottom - top)]
    return [piece for piece in pieces if piece.width > 0 and piece.height > 0]


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
