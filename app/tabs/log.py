"""Log: what happened in this session, oldest first, as the event log keeps it
(``app/event_log.py``): E-stops and releases, faults, limits, moves and their results,
gain changes, link and UI losses, loop stalls. The same entries are in the session's
``events.jsonl`` in the data directory; the path is shown above the table."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.widgets import DataTable, Static

from app.desk import Desk
from app.event_log import LogEntry
from app.tabs.tab import TabPage

COLUMNS = ("time", "what", "joint", "")
KIND_STYLES = {"E-stop": "bold red", "controller died": "bold red", "release": "green",
               "fault": "yellow", "limit": "yellow", "stall": "yellow", "link lost": "yellow",
               "UI lost": "yellow", "link back": "green", "UI back": "green",
               "move start": "cyan", "move end": "cyan", "gains": "magenta"}


class LogTab(TabPage):
    """The session's events in a table that follows the newest while its cursor is on it."""

    REFRESH_HZ = 2.0
    TITLE = "Log"

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.shown_count = 0  # entries of the log already in the table

    def compose(self) -> ComposeResult:
        yield Static(id="log-file")
        yield DataTable(id="log-table", cursor_type="row", zebra_stripes=True)

    def on_mount(self) -> None:
        self.query_one("#log-table", DataTable).add_columns(*COLUMNS)

    def focus_main(self) -> None:
        self.query_one("#log-table", DataTable).focus()

    def refresh_live(self) -> None:
        log = self.desk.events
        self.query_one("#log-file", Static).update(self._file_line())
        new = log.since(self.shown_count)
        self.shown_count = log.count
        if not new:
            return
        table = self.query_one("#log-table", DataTable)
        following = table.row_count == 0 or table.cursor_row >= table.row_count - 1
        for entry in new:
            table.add_row(*_cells(entry))
        if following:
            table.move_cursor(row=table.row_count - 1)

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
