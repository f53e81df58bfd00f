"""The tabs, F1…F11, every one of them on the bar at any width the app supports.

At 80 columns the full labels ("F9 Positions") take 120 columns and the last tabs fell
off the bar; the bar then takes the first of these that fits: full labels, short labels
("F9 Pos"), short labels with one column between tabs instead of two, three-letter ones
("F2 Mov") so.
"""

from __future__ import annotations

from textual import events
from textual.widgets import TabbedContent, TabPane

SHORT = {"Moves": "Move", "Status": "Stat", "Tuning": "Tune", "Latency": "Lat",
         "Identify": "Ident", "Positions": "Pos", "Program": "Prog"}
TINY = {**SHORT, "Moves": "Mov", "Scope": "Scp", "Status": "Sta", "Tuning": "Tun",
        "Runs": "Run", "Identify": "Id", "Program": "Prg"}  # 80 columns hold eleven of these
PADDED = 2  # Textual's Tab pads its label by one column each side


def short_label(label: str, names: dict[str, str] = SHORT) -> str:
    """"F9 Positions" -> "F9 Pos": the key whole, the tab's name shortened."""
    key, _, name = label.partition(" ")
    return f"{key} {names.get(name, name)}"


class TabBar(TabbedContent):
    """A ``TabbedContent`` whose tab labels shorten to fit the bar's width."""

    DEFAULT_CSS = """
    TabBar.-compact ContentTab {
        padding: 0 0 0 1;
    }
    """

    _full: dict[str, str] | None = None  # each pane's label as composed, by the pane's id

    def on_resize(self, event: events.Resize) -> None:
        self.fit(event.size.width)

    def fit(self, width: int) -> None:
        """Full labels if they fit in ``width`` columns, else short, else short and close,
        else three letters and close."""
        panes = list(self.query(TabPane).results(TabPane))
        if self._full is None:
            self._full = {pane.id: str(self.get_tab(pane).label) for pane in panes}
        full = [self._full[pane.id] for pane in panes]
        short = [short_label(label) for label in full]
        if sum(len(label) + PADDED for label in full) <= width:
            labels, compact = full, False
        else:
            labels = short
            compact = sum(len(label) + PADDED for label in short) > width
            if compact and sum(len(label) + 1 for label in short) > width:
                labels = [short_label(label, TINY) for label in full]
        self.set_class(compact, "-compact")
        for pane, label in zip(panes, labels, strict=True):
            tab = self.get_tab(pane)
            if str(tab.label) != label:
                tab.label = label
