"""Text that changes many times a second without re-laying out the screen.

``Static.update`` asks for a layout pass (its size may change), which re-flows
every visible widget; at 10–25 updates a second that is most of the UI's CPU.
A ``LiveText`` has its size fixed by its stylesheet and only repaints.
"""

from __future__ import annotations

from rich.console import RenderableType
from rich.text import Text
from textual.widget import Widget


class LiveText(Widget):
    """A renderable shown as is; ``show`` repaints it in place."""

    def __init__(self, renderable: RenderableType = "", *, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._renderable: RenderableType = renderable

    def show(self, renderable: RenderableType) -> None:
        self._renderable = renderable
        self.refresh()

    def render(self) -> RenderableType:
        return self._renderable

    @property
    def text(self) -> str:
        """The plain text shown (tests, screen readers of the smoke test)."""
        r = self._renderable
        return r.plain if isinstance(r, Text) else str(r)
