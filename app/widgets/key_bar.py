"""The footer: the keys that work here and now, on one line, each one clickable.

Textual's ``Footer`` builds a widget per key and builds them all again whenever the focus
moves: some 30 widgets styled and laid out on every tab switch, 20-40 ms of the UI
thread's time (``benchmarks/ui.py --pauses``), which a busy machine turns into pauses the
client's heartbeat feels. This bar is one widget that renders the same bindings as one
line of text when they change: the key bold, its description beside it, a disabled one
dim, and a click on either presses the key (in ``servodesk serve``'s browser too).
"""

from __future__ import annotations

from textual.content import Content
from textual.screen import Screen
from textual.widgets import Static

FIRST = "estop"  # the app's E-stop action


class KeyBar(Static):
    """The active screen's shown bindings, as Textual's ``Footer`` lists them."""

    DEFAULT_CSS = """
    KeyBar {
        dock: bottom;
        height: 1;
        width: 1fr;
        text-wrap: nowrap;
        text-overflow: ellipsis;
        color: $footer-foreground;
        background: $footer-background;
        link-style: none;
        link-style-hover: none;
        link-background-hover: $block-hover-background;
    }
    """

    def on_mount(self) -> None:
        self.screen.bindings_updated_signal.subscribe(self, self._bindings_changed)
        self._bindings_changed(self.screen)

    def _bindings_changed(self, screen: Screen) -> None:
        if self.is_attached and screen is self.screen:
            self.update(self.line(screen))

    def line(self, screen: Screen) -> Content:
        """Each action once: the E-stop first, so that no width hides it, then the rest in
        the order their first shown binding comes (the focused tab's, then the app's)."""
        seen: set[str] = set()
        parts = []
        active = sorted(screen.active_bindings.values(), key=lambda a: a.binding.action != FIRST)
        for _, binding, enabled, _ in active:
            if not binding.show or binding.action in seen:
                continue
            seen.add(binding.action)
            key = self.app.get_key_display(binding)
            click = f"app.simulate_key({binding.key.split(',')[0]!r})"
            part = Content.from_markup(
                f"[@click={click}][b $footer-key-foreground] $key [/]$description [/]",
                key=key, description=binding.description)
            parts.append(part if enabled else part.stylize("dim"))
        return Content(" ").join(parts) if parts else Content("")
