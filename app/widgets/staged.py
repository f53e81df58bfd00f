"""A widget drawn in parts the first time it is shown.

Textual draws every widget that comes into view in one screen refresh, and the first time
each is drawn nothing of it is cached: 35-70 ms for the Moves tab at 160 × 48 on the
development machine, half as much again beside a CPU burner, the UI's longest pause. A
``Staged`` widget's ``LATER`` parts are hidden (their room kept, so nothing moves) until it
is first shown, then drawn one part a refresh, so the longest pause is its largest part's
(``python benchmarks/ui.py --pauses``)."""

from __future__ import annotations

from typing import ClassVar

from textual.widget import Widget


class Staged(Widget):
    """``LATER``: selectors of the parts drawn after the rest, each a refresh after the one
    before. ``hide_later`` when mounted, ``reveal_later`` when shown (only the first call
    draws anything)."""

    LATER: ClassVar[tuple[str, ...]] = ()
    _unrevealed: list[str] | tuple[()] = ()
    _revealing = False

    def hide_later(self) -> None:
        self._unrevealed = list(self.LATER)
        for selector in self._unrevealed:
            self.query(selector).set_styles("visibility: hidden;")

    def reveal_later(self) -> None:
        if self._unrevealed and not self._revealing:  # shown again before the first refresh
            self._revealing = True
            self.call_after_refresh(self._reveal_next)

    def _reveal_next(self) -> None:
        self.query(self._unrevealed.pop(0)).set_styles("visibility: visible;")
        if self._unrevealed:
            self.call_after_refresh(self._reveal_next)
