"""The tabs' screen, drawn by the rows that changed.

For a partial update (a few numbers changed) Textual's compositor draws every widget whose
parent's area meets the box around all the changes, and every line of each: the screen's 48
lines, the tab bar's 44, each container's 42, to send the terminal the one row of cells that
changed. At 10 updates a second that was most of an idle tab's CPU. Here a widget is drawn
only if what it shows meets a changed region, and only over the rows from the first changed
row it shows to the last: the terminal is sent the same cells, fewer are drawn.
"""

from __future__ import annotations

from collections.abc import Iterable

from textual._compositor import ChopsUpdate, Compositor
from textual.geometry import Region
from textual.screen import Screen
from textual.strip import Strip


class ChangedRowsCompositor(Compositor):
    """A compositor whose partial updates draw only the widgets a change reaches, and only
    the rows of them it reaches (full updates are drawn as before)."""

    def __init__(self) -> None:
        super().__init__()
        self._changed: list[Region] | None = None  # while a partial update is drawn

    def render_partial_update(self) -> ChopsUpdate | None:
        self._changed = list(self._dirty_regions)
        try:
            return super().render_partial_update()
        finally:
            self._changed = None

    def _get_renders(self, crop: Region | None = None
                     ) -> Iterable[tuple[Region, Region, list[Strip]]]:
        changed = self._changed
        if not changed or crop is None:  # a full update: every widget, whole
            yield from super()._get_renders(crop)
            return
        for widget, (region, clip) in self.visible_widgets.items():
            shown = region.intersection(clip)
            if not crop.overlaps(shown):  # most widgets: away from every change
                continue
            reached = [shown.intersection(c) for c in changed if shown.overlaps(c)]
            if not reached:  # nothing of it is sent: its cells are not in any change
                continue
            top = min(r.y for r in reached)
            rows = Region(shown.x, top, shown.width, max(r.bottom for r in reached) - top)
            # the rows as the widget's own clip: the compositor places them where they are
            yield region, clip.intersection(rows), widget.render_lines(
                rows.translate((-region.x, -region.y)))


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
