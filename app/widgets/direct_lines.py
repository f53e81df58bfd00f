"""Widgets whose lines go to the screen as their ``render_line`` draws them.

Textual hands a widget's lines to the screen through its styles cache, which adds the
border, padding, outline, hatch, tint and opacity, and the app's line filters. For a widget
with none of these whose ``render_line`` draws each line whole at its width, the cache gives
back the very line it was given; but each call walks every ancestor for the background and
the opacity and reads the styles again: on an idle Status tab the three calls a tick cost
more than drawing the lines that changed, and the Scope's seven a frame as much.
"""

from __future__ import annotations

from textual.color import Color
from textual.filter import LineFilter
from textual.geometry import Region, Spacing
from textual.strip import Strip
from textual.widget import Widget

NO_SPACE = Spacing(0, 0, 0, 0)


class DirectLines(Widget):
    """A widget whose lines, when it has no box of its own (``boxless``), are its
    ``render_line``'s, filtered by the app's line filters: its ``render_line`` must give a line
    of exactly its width."""

    # found once, until a stylesheet change reaches the widget: whether it is boxless, and the
    # background the line filters are given (found by walking every ancestor)
    _boxless: bool | None = None
    _background: Color | None = None

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._boxless = None
        self._background = None

    def direct(self) -> bool:
        """Whether the lines are drawn directly now (a subclass may say not, then and there)."""
        boxless = self._boxless
        if boxless is None:
            boxless = self._boxless = boxless_widget(self)
        return boxless

    def render_lines(self, crop: Region) -> list[Strip]:
        if not self.direct():
            return super().render_lines(crop)
        width = self.size.width
        filters = tuple(self.app.get_line_filters())
        background = self._background
        if filters and background is None:
            background = self._background = self.background_colors[1]
        strips = [self.filtered_line(y, width, filters, background) for y in crop.line_range]
        x1, x2 = crop.column_span
        if (x1, x2) != (0, width):
            strips = [strip.crop(x1, x2) for strip in strips]
        return strips

    def filtered_line(self, y: int, width: int, filters: tuple[LineFilter, ...],
                      background: Color | None) -> Strip:
        """Line ``y`` as ``render_line`` draws it (``width`` wide), through ``filters``."""
        return through(self.render_line(y), filters, background)


def through(strip: Strip, filters: tuple[LineFilter, ...], background: Color | None) -> Strip:
    """``strip`` through the app's line ``filters`` in turn, on ``background``."""
    for line_filter in filters:
        strip = strip.apply_filter(line_filter, background)  # type: ignore[arg-type]
    return strip


def boxless_widget(widget: Widget) -> bool:
    """Whether Textual's styles cache would leave ``widget``'s content lines as they are:
    no border, outline, padding, border title, hatch, tint or opacity (its own or an
    ancestor's), and its content the whole widget."""
    styles = widget.styles
    return (styles.padding == NO_SPACE
            and not any(edge for edge, _ in styles.border)
            and not any(edge for edge, _ in styles.outline)
            and widget._border_title is None and widget._border_subtitle is None
            and not (styles.has_rule("hatch") and styles.hatch != "none")
            and not styles.tint.a and styles.text_opacity == 1.0 and widget.opacity == 1.0
            and widget.BLANK is False)
