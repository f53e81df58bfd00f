"""A bare Textual app the size of the TUI's Jog screen, the base of ``benchmarks/ui.py``'s idle
and start figures: a three-line header whose last line changes ten times a second (a tick
count, as the TUI's loop line does), a tab bar of ten tabs, one tab of seven lines and a key
bar (32 widgets shown, as on the Jog tab). No controller, no numpy, nothing of servodesk's.

Run: ``python benchmarks/textual_peer.py`` (in a terminal: ^Q quits)."""

from __future__ import annotations

from typing import ClassVar

from textual.app import App, ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widget import Widget
from textual.widgets import Footer, Static, TabbedContent, TabPane

HZ = 10.0  # the TUI's status rate
TABS = 10
LINES = 7


class Ticker(Widget):
    """One line that repaints in place, as the TUI's LiveText does."""

    DEFAULT_CSS = "Ticker { height: 1; }"

    def __init__(self) -> None:
        super().__init__(id="ticker")
        self.count = 0

    def tick(self) -> None:
        self.count += 1
        self.refresh()

    def render(self) -> str:
        return f"loop late 1.0 µs  compute 80.0 µs  overruns 0  tick {self.count}"


class Peer(App[None]):
    BINDINGS: ClassVar = [("ctrl+q", "quit", "quit")]
    CSS = "#head { height: 3; } #lamp { width: 30; } #lines Static { height: 1; }"

    def compose(self) -> ComposeResult:
        with Horizontal(id="head"):
            with Vertical():
                yield Static("peer  a bare Textual app", id="identity")
                yield Static("link ok   mode HOLD", id="health")
                yield Ticker()
            yield Static("RUN", id="lamp")
        with TabbedContent():
            for k in range(TABS):
                with TabPane(f"F{k + 1} Tab"):
                    if k == 0:
                        with Vertical(id="lines"):
                            for i in range(LINES):
                                yield Static(f"line {i}")
        yield Footer()

    def on_mount(self) -> None:
        self.set_interval(1.0 / HZ, self.query_one(Ticker).tick)


if __name__ == "__main__":
    Peer().run()
