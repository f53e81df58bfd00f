"""Log: what happened in this session, oldest first, as the event log keeps it
(``app/event_log.py``): E-stops and releases, faults, limits, moves and their results,
feed changes, gain changes and refusals, positions taught, changes of command, link and UI
losses, loop stalls, the session's start. The same entries are in the session's
``events.jsonl`` in the data directory; the path is shown above the table.

The table follows the newest entry as ``tail -f`` does, unless the operator has moved back
up it; End goes to the newest row and Home to the oldest, and the time column stays in
view however far the table is scrolled sideways."""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.widgets import DataTable, Static

from app.desk import Desk
from app.event_log import LogEntry
from app.tabs.tab import TabPage

COLUMNS = ("time", "what", "joint", "")
KIND_STYLES = {"E-stop": "bold red", "controller died": "bold red", "release": "green",
               "fault": "yellow", "limit": "yellow", "stall": "yellow", "link lost": "yellow",
               "UI lost": "yellow", "link back": "green", "UI back": "green",
               "limit clear": "green", "move start": "cyan", "move end": "cyan",
               "gains": "magenta", "feed": "cyan", "command": "magenta",
               "command lost": "bold yellow", "refused": "yellow", "position": "cyan",
               "session": "dim"}


class LogTable(DataTable):
    """The log's rows: Home and End go to the oldest and the newest entry (a table's own
    go to its first and last column, scrolling the time column out of view)."""

    BINDINGS: ClassVar = [
        Binding("home", "scroll_top", "oldest", show=False),
        Binding("end", "scroll_bottom", "newest", show=False),
    ]

    @property
    def at_newest(self) -> bool:
        """The cursor is on the newest row and the view shows it (not scrolled back up)."""
        return self.row_count == 0 or (self.cursor_row >= self.row_count - 1
                                       and self.scroll_y >= self.max_scroll_y - 1)

    def to_newest(self) -> None:
        if self.row_count:
            self.move_cursor(row=self.row_count - 1, animate=False)


class LogTab(TabPage):
    """The session's events in a table that follows the newest unless scrolled back."""

    REFRESH_HZ = 2.0
    TITLE = "Log"

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.shown_count = 0  # entries of the log already in the table

    def compose(self) -> ComposeResult:
        yield Static(id="log-file")
        yield LogTable(id="log-table", cursor_type="row", zebra_stripes=True, fixed_columns=1)

    def on_mount(self) -> None:
        self.query_one(LogTable).add_columns(*COLUMNS)

    def focus_main(self) -> None:
        self.query_one(LogTable).focus()

    def shown(self) -> None:
        table = self.query_one(LogTable)
        following = table.cursor_row >= table.row_count - 1  # where it was left
        super().shown()
        if following:  # laid out only now: the newest row into view
            self.call_after_refresh(table.to_newest)

    def refresh_live(self) -> None:
        log = self.desk.events
        self.query_one("#log-file", Static).update(self._file_line())
        new = log.since(self.shown_count)
        self.shown_count = log.count
        if not new:
            return
        table = self.query_one(LogTable)
        following = table.at_newest
        for entry in new:
            table.add_row(*_cells(entry))
        if following:
            table.to_newest()

    def _file_line(self) -> Text:
        log = self.desk.events
        if log.problem:
            return Text(log.problem, "bold red")
        where = str(log.path) if log.path is not None else "not written (no session folder)"
        return Text.assemble(("this session's log: ", "dim"), where,
                             (f"  ·  {log.count} entries", "dim"))


def _cells(entry: LogEntry) -> tuple[Text, Text, Text, Text]:
    style = KIND_STYLES.get(entry.kind, "")
    return (Text(entry.clock, "dim"), Text(entry.kind, style), Text(entry.joint),
            Text(entry.what))
