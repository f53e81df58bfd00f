"""Text that changes many times a second without re-laying out the screen.

``Static.update`` asks for a layout pass (its size may change), which re-flows
every visible widget; at 10–25 updates a second that is most of the UI's CPU.
A ``LiveText`` has its size fixed by its stylesheet and only repaints, and only
when what it shows has changed: most of a live screen is the same from one tick to
the next, and repainting it identical cost an idle tab a quarter of a core.
"""

from __future__ import annotations

import math
from collections.abc import Hashable

from rich.cells import cell_len
from rich.console import Group, RenderableType
from rich.segment import Segment, Segments
from rich.style import Style
from rich.table import Table
from rich.text import Text
from textual.color import Color
from textual.filter import LineFilter
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

from app.widgets.direct_lines import DirectLines, through
from app.widgets.limit_bar import LimitBar

BAR_STEPS = 10_000  # a limit bar's marks compared to a ten-thousandth of its range: finer
# than any terminal draws it


class LiveText(Widget):
    """A renderable shown as is; ``show`` repaints it in place when it differs."""

    def __init__(self, renderable: RenderableType = "", *, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._renderable: RenderableType = renderable
        self._shown: RenderableType = renderable  # what render() hands Textual
        self._key: Hashable | None = fingerprint(renderable)  # what is shown, in brief
        self._lines: list[list[Segment]] | None = None  # or the lines it drew, as last shown
        self.repaints = 0  # how many times a change was shown (tests of the idle cost)

    def show(self, renderable: RenderableType) -> None:
        self._renderable = renderable
        key = fingerprint(renderable)
        if key is not None:  # compared by what it says: cheaper than drawing it
            if key == self._key:
                return
            self._key, self._shown, self._lines = key, renderable, None
        else:  # something else: compared as the lines it draws at this width
            width = self.size.width
            lines = (self.app.console.render_lines(
                renderable, self.app.console.options.update_width(width), pad=False)
                if width > 0 else None)
            if lines is not None and lines == self._lines:
                return
            self._key, self._lines = None, lines
            self._shown = renderable if lines is None else _segments(lines)
        self.repaints += 1
        self.refresh()

    def on_resize(self) -> None:
        if self._lines is not None:  # drawn for the old width: draw it again
            self._lines = None
            self.show(self._renderable)

    def render(self) -> RenderableType:
        return self._shown

    @property
    def text(self) -> str:
        """The plain text shown (tests, screen readers of the smoke test)."""
        r = self._renderable
        if isinstance(r, Text):
            return r.plain
        if self._lines is not None:
            return "\n".join("".join(s.text for s in line) for line in self._lines)
        return str(r)


def _segments(lines: list[list[Segment]]) -> Segments:
    """Lines already drawn, as one renderable."""
    out: list[Segment] = []
    for i, line in enumerate(lines):
        if i:
            out.append(Segment.line())
        out.extend(line)
    return Segments(out)


class LiveLines(LiveText, DirectLines):
    """A ``LiveText`` of many lines of which a few change each time (Status' blocks): a
    ``Text`` shown (or its lines, ``show_rows``) is compared line by line, and only the lines
    that changed are drawn again (each one line, cut at the widget's width; other renderables
    are drawn whole)."""

    def __init__(self, renderable: RenderableType = "", *, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(renderable, id=id, classes=classes)
        self._rows: list[Text] | None = None  # the Text shown, line by line
        self._strips: list[Strip | None] = []  # each line drawn, None until it is again
        # each line drawn through the app's line filters (for _filtered_by: the filters and
        # the background): filters change colours, never characters, so a line whose few
        # characters changed has them written into its filtered line as into its line
        self._filtered: list[Strip | None] = []
        self._filtered_by: tuple[object, ...] = ()
        # the style its lines are drawn in: found once, not per line (it walks every ancestor,
        # two thirds of a line's cost), until a stylesheet change reaches the widget
        self._style: Style | None = None

    def show(self, renderable: RenderableType) -> None:
        if renderable is self._renderable and self._rows is not None:  # the very Text shown
            return
        if not isinstance(renderable, Text):
            self._rows = None
            super().show(renderable)
            return
        self._renderable = renderable
        self._show_rows(renderable.split("\n", allow_blank=True))

    def show_rows(self, rows: list[Text]) -> None:
        """Show ``rows``, a ``Text`` a line (each drawn as one line, cut at the width): what a
        live block makes line by line need not be joined to be split again here."""
        if rows is self._renderable and self._rows is not None:  # the very rows shown
            return
        self._renderable = rows
        self._show_rows(rows)

    def _show_rows(self, rows: list[Text]) -> None:
        before = self._rows
        self._rows, self._key, self._lines = rows, None, None
        if before is None or len(before) != len(rows):
            self._forget_strips(len(rows))
            self.repaints += 1
            self.refresh()
            return
        width = self.size.width
        changed = [Region(x, y, w, 1) for y, (old, new) in enumerate(zip(before, rows, strict=True))
                   if old is not new and not _same(old, new)  # most lines: the very line kept
                   for x, w in [changed_cells(old, new, width)]]
        for x, y, w, _ in changed:
            # a few characters changed, in the styles they had: those written into the line
            # drawn, not the whole line drawn again (a joint's glitch count, every tick)
            for strips in (self._strips, self._filtered):
                strip = strips[y]
                strips[y] = (None if strip is None or w >= width or strip.cell_length != width
                             else with_characters(strip, rows[y].plain, x, x + w))
        if changed:
            self.repaints += 1
            self.refresh(*changed)

    @property
    def text(self) -> str:
        if self._rows is not None:
            return "\n".join(row.plain for row in self._rows)
        return super().text

    def _forget_strips(self, lines: int) -> None:
        self._strips = [None] * lines
        self._filtered = [None] * lines

    def on_resize(self) -> None:
        self._forget_strips(len(self._strips))
        super().on_resize()

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._style = None
        self._forget_strips(len(self._strips))

    def direct(self) -> bool:
        return self._rows is not None and super().direct()  # a Text's lines: drawn whole

    def filtered_line(self, y: int, width: int, filters: tuple[LineFilter, ...],
                      background: Color | None) -> Strip:
        if self._rows is None or y >= len(self._filtered):
            return super().filtered_line(y, width, filters, background)
        if (filters, background) != self._filtered_by:
            self._filtered_by = (filters, background)
            self._filtered = [None] * len(self._filtered)
        strip = self._filtered[y]
        if strip is None or strip.cell_length != width:
            strip = self._filtered[y] = through(self._line(y, width), filters, background)
        return strip

    def render_line(self, y: int) -> Strip:
        if self._rows is None:
            return super().render_line(y)
        return self._line(y, self.size.width)

    def _line(self, y: int, width: int) -> Strip:
        """Line ``y`` of the rows shown, drawn ``width`` wide (kept until it changes)."""
        style = self._style
        if style is None:
            style = self._style = self.rich_style
        if y >= len(self._rows):
            return Strip.blank(width, style)
        strip = self._strips[y]
        if strip is None or strip.cell_length != width:
            line = self._rows[y]
            strip = (Strip(list(line.render(self.app.console)))  # cut or padded to the width
                     .adjust_cell_length(width).apply_style(style))
            self._strips[y] = strip
        return strip


def with_characters(strip: Strip, plain: str, start: int, end: int) -> Strip:
    """``strip`` with its cells from ``start`` to ``end`` (cut at its length) the characters of
    ``plain`` there, each in the style its cell had: the line ``plain`` draws, when it differs
    from the one ``strip`` drew only there and every character of both is one cell wide."""
    end = min(end, strip.cell_length)
    segments, at = [], 0
    for segment in strip:
        text = segment.text
        after = at + len(text)
        if after > start and at < end:
            left, right = max(start, at), min(end, after)
            text = text[:left - at] + plain[left:right].ljust(right - left) + text[right - at:]
            segment = Segment(text, segment.style, segment.control)
        segments.append(segment)
        at = after
    return Strip(segments, strip.cell_length)


def _same(a: Text, b: Text) -> bool:
    """``fingerprint(a) == fingerprint(b)`` for two texts, the words compared first (most
    lines of a live block read as before) and no tuple made of either."""
    return (a.plain == b.plain and a.spans == b.spans and a.style == b.style
            and a.justify == b.justify and a.no_wrap == b.no_wrap and a.overflow == b.overflow)


def changed_cells(old: Text, new: Text, width: int) -> tuple[int, int]:
    """The columns ``(x, width)`` of a line that differ from ``old`` to ``new``: the screen
    updates the smallest box around every change, and a box narrower than the screen leaves
    out the widgets beside it (Status' pose and link blocks, the header's lamp). The whole
    line when the styles changed or a character is not one cell wide."""
    a, b = old.plain, new.plain
    if (a == b or old.spans != new.spans or old.style != new.style or len(a) != len(b)
            or cell_len(a) != len(a) or cell_len(b) != len(b)):
        return 0, width
    # the first and the last character that differ, found by halving (slices compare in C)
    lo, hi = 0, len(a)  # a[:lo] == b[:lo], a[:hi] != b[:hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if a[:mid] == b[:mid] else (lo, mid)
    first = lo
    lo, hi = first, len(a)  # a[hi:] == b[hi:], a[lo:] != b[lo:]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if a[mid:] == b[mid:] else (mid, hi)
    return first, lo - first + 1


def fingerprint(renderable: RenderableType) -> Hashable | None:
    """What ``renderable`` says, as a value equal for two that draw the same at any width
    (text, tables and groups of them, limit bars); None for anything else."""
    if isinstance(renderable, str):
        return renderable
    if isinstance(renderable, Text):
        return (renderable.plain, tuple(renderable.spans), renderable.style,
                renderable.justify, renderable.no_wrap, renderable.overflow)
    if isinstance(renderable, LimitBar):
        return (_bar_step(renderable, renderable.position),
                _bar_step(renderable, renderable.desired), renderable.width)
    if isinstance(renderable, Group):
        parts = tuple(fingerprint(r) for r in renderable.renderables)
        return None if None in parts else ("group", parts)
    if isinstance(renderable, Table):
        columns = tuple((fingerprint(c.header), c.justify, c.ratio, c.width, c.min_width,
                         tuple(fingerprint(cell) for cell in c._cells))
                        for c in renderable.columns)
        cells = [cell for column in columns for cell in column[5]]
        if None in cells or any(c[0] is None for c in columns):
            return None
        title = renderable.title
        return ("table", columns, None if title is None else fingerprint(title))
    return None


def _bar_step(bar: LimitBar, value: float) -> tuple[int, bool, bool] | None:
    """Where ``value`` is on ``bar``, to ``BAR_STEPS``, and whether at or past either limit."""
    if not math.isfinite(value):
        return None
    f = bar.fraction(value)
    return (math.floor(f * BAR_STEPS), f <= 0, f >= 1)
