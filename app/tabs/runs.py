"""Runs: every saved move, newest first, and its plots as the thesis drew them in MATLAB.

``plotsix.m`` (desired and actual position beside the duty, per joint; arm
joints 1–3 then wrist joints 4–6, fewer at a time on a small screen) and
``plotdata.m`` (one joint's error, response, duty and estimated velocity). A plot
is exported as an SVG drawn from the run's data, under ``plots/`` next to the
runs. Runs the recorder could not save are kept in memory and listed first, so
they can be saved elsewhere. The moves of one program run (``meta.program``:
``control/program/runner.py``) are listed together, in the order the program made them,
each named by its program, run id and step.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import ClassVar

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Static

from app.desk import Desk
from app.plotting.figure import Figure
from app.plotting.run_plot import export, steady_velocity, view_figure, view_slug, views
from app.plotting.strips import panel_size
from app.run_groups import grouped, program_cell, program_of
from app.run_text import local_time, run_lines
from app.tabs.tab import TabPage
from app.widgets.figure_plot import FigurePlot
from control.recorder import RecorderError, Run, RunInfo, list_runs, load_run, save_run
from control.run_mcap import write_mcap


class RunsTab(TabPage):
    """The list of runs and the plot of the one opened."""

    TITLE = "Runs"
    LATER = ("#runs-right",)
    BINDINGS: ClassVar = [
        Binding("v", "next_view", "next plot"),
        Binding("x", "export", "export plot"),
        Binding("m", "export_mcap", "export MCAP"),
        Binding("r", "reload", "refresh list"),
        Binding("s", "save_unsaved", "save unsaved run", show=False),
    ]

    @dataclass
    class Listed(Message, bubble=False):
        """The runs in the data directory, newest first, a program run's together in its
        order (from the listing worker); ``programs``: each program run's ``meta.program``
        by the run's stem."""

        infos: list[RunInfo]
        programs: dict[str, dict] = field(default_factory=dict)

    @dataclass
    class Opened(Message, bubble=False):
        """A run was read from its files (from the loading worker)."""

        run: Run
        name: str

    @dataclass
    class Saved(Message, bubble=False):
        """An unsaved run was saved to ``where`` (from the saving worker)."""

        run: Run
        where: Path

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.infos: list[RunInfo] = []
        self.unsaved: list[Run] = []
        self.run: Run | None = None
        self.run_name = ""
        self.view = 0
        self.stale = True

    def compose(self) -> ComposeResult:
        with Horizontal():
            with Vertical(id="runs-left"):
                yield DataTable(id="runs-table", cursor_type="row", zebra_stripes=True)
                yield Static(id="runs-meta")
                with Horizontal(id="runs-save"):
                    yield Input(str(Path.home() / "servodesk-runs"), id="runs-save-dir",
                                compact=True)
                    yield Button("Save unsaved", id="runs-save-button")
            with Vertical(id="runs-right"):
                yield Static(id="runs-bar")
                yield FigurePlot(id="runs-plot")

    def on_mount(self) -> None:
        self.query_one("#runs-table", DataTable).add_columns("started", "kind", "status",
                                                             "samples", "program")
        self.query_one("#runs-save").display = False

    def focus_main(self) -> None:
        self.query_one("#runs-table", DataTable).focus()

    def shown(self) -> None:
        super().shown()
        if self.stale:
            self.action_reload()

    def mark_stale(self) -> None:
        """A run was saved: list it now if visible, else when next shown."""
        self.stale = True
        if self.visible_now:
            self.action_reload()

    def keep_unsaved(self, run: Run) -> None:
        self.unsaved.insert(0, run)
        self.mark_stale()

    # -- the list -------------------------------------------------------------------------

    def action_reload(self) -> None:
        self.stale = False
        self._list()

    @work(thread=True, exclusive=True, group="runs-list")
    def _list(self) -> None:
        infos = list_runs(self.desk.data_dir)
        programs = {i.files.stem: p for i in infos if (p := program_of(i)) is not None}
        self.post_message(self.Listed(grouped(infos, programs), programs))

    def on_runs_tab_listed(self, message: Listed) -> None:
        infos = self.infos = message.infos
        table = self.query_one("#runs-table", DataTable)
        table.clear()
        for i, run in enumerate(self.unsaved):
            table.add_row(local_time(run.start_time), run.kind,
                          Text("NOT SAVED", "bold red"), str(run.samples),
                          program_cell(run.meta.get("program")), key=f"unsaved-{i}")
        for info in infos:
            if info.damaged:
                table.add_row("?", info.files.stem, Text("damaged", "red"), "", "",
                              key=info.files.stem)
                continue
            style = "green" if info.status == "complete" else "yellow"
            table.add_row(local_time(info.start_time), info.kind, Text(info.status[:28], style),
                          str(info.samples), program_cell(message.programs.get(info.files.stem)),
                          key=info.files.stem)
        self.query_one("#runs-meta", Static).update(Text(
            f"{len(infos)} run(s) in {self.desk.data_dir}" if infos or self.unsaved else
            f"no runs yet in {self.desk.data_dir}: run a move from the Moves tab", "dim"))

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        key = event.row_key.value or ""
        self.query_one("#runs-save").display = key.startswith("unsaved-")
        if key.startswith("unsaved-"):
            run = self.unsaved[int(key.split("-")[1])]
            self._opened(run, f"unsaved {run.kind}")
            return
        info = next((i for i in self.infos if i.files.stem == key), None)
        if info is None or info.damaged:
            self.notify(f"{key}: {info.problem if info else 'not found'}; the files are left "
                        "as they are", severity="error")
            return
        self._load(info)

    @work(thread=True, exclusive=True, group="runs-load")
    def _load(self, info: RunInfo) -> None:
        try:
            run = load_run(info.files.json)
        except RecorderError as exc:
            self.notify(f"cannot open the run: {exc}", severity="error")
            return
        self.post_message(self.Opened(run, info.files.stem))

    def open_latest(self) -> None:
        """Open the newest run (after the list was loaded)."""
        table = self.query_one("#runs-table", DataTable)
        if table.row_count:
            table.move_cursor(row=0)
            table.action_select_cursor()

    # -- the plot -------------------------------------------------------------------------

    def views(self) -> list[str]:
        """The plots of the open run: plotsix of as many joints as the plot has room for
        (the thesis's three), then plotdata of each joint."""
        return [] if self.run is None else views(self.run, self.joints_per_view())

    def joints_per_view(self) -> int:
        """How many joints a plotsix view shows: three, or as many as the plot can hold."""
        height = self.query_one("#runs-plot", FigurePlot).size.height
        return max(1, min(3, height // panel_size().height))

    def on_runs_tab_opened(self, message: Opened) -> None:
        self._opened(message.run, message.name)

    def _opened(self, run: Run, name: str) -> None:
        self.run = run
        self.run_name = name
        self.view = 0
        lines = run_lines(run, name)
        if isinstance(program := run.meta.get("program"), dict):
            lines.append(f"program {program.get('name')}, run {program.get('run_id')}, step "
                         f"{program.get('step')} ({program.get('title')})")
        self.query_one("#runs-meta", Static).update("\n".join(lines))
        self.draw()

    def action_next_view(self) -> None:
        if self.run is not None:
            self.view = (self.view + 1) % len(self.views())
            self.draw()

    def draw(self) -> None:
        run = self.run
        if run is None:
            return
        views = self.views()
        self.view = min(self.view, len(views) - 1)
        figure = self.figure()
        view = views[self.view]
        plot = self.query_one("#runs-plot", FigurePlot)
        # plotdata on a short screen: the response and its error, the panels that matter most
        plot.show(figure, replace(figure, panels=figure.panels[:2]))
        extra = ""
        if view.startswith("plotdata"):
            j = run.joint_names.index(view.split(" ", 1)[1])
            extra = (f" · steady velocity {steady_velocity(run.t, run.actual[:, j]):+.4g} "
                     f"{run.joint_units[j]}/s")
        if plot.drawn is not None and plot.drawn is not figure:
            extra += f" · {len(plot.drawn.panels)} of {len(figure.panels)} panels (x exports all)"
        self.query_one("#runs-bar", Static).update(Text.assemble(
            (view, "bold"), extra, ("   v next plot · x export", "dim")))

    def on_resize(self) -> None:
        if self.run is not None:
            self.draw()  # a plotsix view holds as many joints as fit

    def figure(self) -> Figure:
        """The figure of the current view."""
        run = self.run
        assert run is not None
        return view_figure(run, self.views()[self.view], f"{self.run_name} · {run.status}")

    def action_export(self) -> None:
        if self.run is None:
            self.notify("open a run first (Enter on the list)", severity="warning")
            return
        view = view_slug(self.views()[self.view])
        stem = self.run_name.replace(" ", "-")
        self._export(self.desk.data_dir / "plots" / f"{stem}-{view}", self.figure())

    @work(thread=True, group="runs-export")
    def _export(self, path: Path, figure: Figure) -> None:
        try:
            written = export(path, figure)
        except OSError as exc:
            self.notify(f"cannot export to {path}: {exc}; check the data directory is writable",
                        severity="error")
            return
        self.notify("exported " + ", ".join(str(p) for p in written))

    def action_export_mcap(self) -> None:
        """The whole run as MCAP, for Foxglove or PlotJuggler (``control/run_mcap.py``)."""
        if self.run is None:
            self.notify("open a run first (Enter on the list)", severity="warning")
            return
        stem = self.run_name.replace(" ", "-")
        self._export_mcap(self.run, self.desk.data_dir / "exports" / f"{stem}.mcap")

    @work(thread=True, group="runs-export")
    def _export_mcap(self, run: Run, path: Path) -> None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_mcap(run, path)
        except OSError as exc:
            self.notify(f"cannot export to {path}: {exc}; check the data directory is writable",
                        severity="error")
            return
        self.notify(f"exported {path}")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "runs-save-button":
            event.stop()
            self.action_save_unsaved()

    def action_save_unsaved(self) -> None:
        if self.run is None or not any(r is self.run for r in self.unsaved):
            self.notify("select a NOT SAVED run first", severity="warning")
            return
        try:  # a TUI that does not command saves only inside the data directory
            directory = self.desk.typed_path(self.query_one("#runs-save-dir", Input).value,
                                             "save the run")
        except ValueError as exc:
            self.notify(str(exc), severity="error", timeout=10)
            return
        self._save(self.run, directory)

    @work(thread=True, group="runs-save")
    def _save(self, run: Run, directory: Path) -> None:
        try:
            files = save_run(run, directory)
        except RecorderError as exc:
            self.notify(f"{exc}; choose another directory", severity="error")
            return
        self.post_message(self.Saved(run, files.json))

    def on_runs_tab_saved(self, message: Saved) -> None:
        self.unsaved = [r for r in self.unsaved if r is not message.run]
        if self.connection is not None:  # the copy kept for the next start is not needed now
            self.connection.release_kept(message.run)
        self.notify(f"saved to {message.where}")
        self.action_reload()
