"""Positions: home and park from the machine file, and positions taught by the operator.

The table lists every position with its joints and, for the Unimate, its pose
(x, y, z, γ, β, α through the forward kinematics, eq. 4.11). ``t`` (or ^T on any
tab) teaches where the joints are under a name; ``g`` goes to the selected one: a
joint-space move at the speed fraction typed (``ControlClient.go_to``: every joint
within that fraction of its max_speed and max_accel), after a confirmation that names the
largest joint travel, the tool's straight-line distance (Unimate) and the planned time, all
read from the path that will run; it leaves its result (tracking and settle per joint) below
the table, as a Moves run does. ``r`` renames, Delete deletes,
``l`` reads the file again after an edit by hand. Only a TUI that commands may teach,
rename or delete (``Desk.refusal``): the commander's go-tos use these names. Taught
positions are kept in the data directory (``control/motion/positions.py``,
``docs/motion.md``); every change reads the file, changes it and writes it atomically in a
worker, so an edit made by hand meanwhile is kept, and a damaged file is reported, never
overwritten.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import DataTable, Static

from app.desk import Desk
from app.event_log import LogEntry
from app.messages import RunsChanged
from app.tabs.status import POSE_LABELS
from app.tabs.tab import TabPage
from app.widgets.dialogs import ConfirmScreen, EditValueScreen
from app.widgets.fields import FieldError, NumberCheck, NumberField
from app.widgets.live_text import LiveText
from control.client import ControlClient, ControllerError, MoveHandle, MoveResult
from control.motion import form_plans
from control.motion.moves import summary_cells, summary_columns
from control.motion.plan import SETTLE_COLUMNS, MovePlan, Summary, settle_cell
from control.motion.positions import (
    Position,
    PositionBook,
    PositionsError,
    load_positions,
    positions_file,
    save_positions,
)

SPEEDS = (0.05, 1.0)  # the speed fraction a go-to may ask for
STACK_UNDER = 110  # columns under which the table stacks the pose under the joints


class PositionsTab(TabPage):
    """List, teach, rename, delete and go to named positions."""

    REFRESH_HZ = 5.0
    TITLE = "Positions"
    LATER = ("#positions-lower",)
    BINDINGS: ClassVar = [
        Binding("t", "teach", "teach here"),
        Binding("g", "go_to", "go to"),
        Binding("r", "rename", "rename"),
        Binding("delete", "delete", "delete", key_display="Del"),
        Binding("l", "reload", "reload file"),
    ]

    @dataclass
    class Changed(Message):
        """The positions are (re)read: every one, home and park first (for the via points)."""

        positions: tuple[Position, ...]

    @dataclass
    class Loaded(Message, bubble=False):
        """The file was read or written (from the file worker): ``done`` says what changed,
        ``select`` names the position to put the cursor on."""

        book: PositionBook
        done: str = ""
        select: str | None = None
        changed: bool = False  # the file was changed (logged), not only read

    @dataclass
    class Problem(Message, bubble=False):
        """The change was refused, or (``in_file``) the file could not be read or written."""

        text: str
        in_file: bool

    @dataclass
    class Arrived(Message, bubble=False):
        """A go-to ended (from the waiting worker): ``away`` names the joints the controller
        did not find in position within the machine's goal_time (empty: there)."""

        name: str
        result: MoveResult
        away: str
        summaries: list[tuple[str, Summary]]

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.path = positions_file(desk.data_dir, desk.machine)
        self.book = PositionBook(desk.machine)
        self.handle: MoveHandle | None = None
        self._file_lock = threading.Lock()  # one read-change-write at a time
        self.stacked = False  # the table's rows two lines each, the pose under the joints

    def compose(self) -> ComposeResult:
        yield DataTable(id="positions-table", cursor_type="row", zebra_stripes=True)
        with Horizontal(id="positions-lower"):
            with Vertical(id="positions-controls"):
                yield NumberField("speed fraction", NumberCheck("speed fraction", "", *SPEEDS),
                                  "0.5", id="positions-speed")
                yield Static(id="positions-file")
            with Vertical():
                yield LiveText(id="positions-here")
                yield LiveText(id="positions-state")
                yield DataTable(id="positions-result", cursor_type="none", zebra_stripes=True)

    def on_mount(self) -> None:
        super().on_mount()
        self._columns()
        self._state(Text("t teaches where the joints are; g goes to the selected position",
                         "dim"))
        self.query_one("#positions-result", DataTable).display = False  # until a go-to ends
        self._change(None)

    def focus_main(self) -> None:
        self.query_one("#positions-table", DataTable).focus()

    # -- the list ------------------------------------------------------------------------------

    def on_resize(self) -> None:
        if self.stacked != self._stack_wanted():
            self._columns()
            self._show(self.book)

    def _stack_wanted(self) -> bool:
        return (self.size.width < STACK_UNDER and self.model is not None
                and self.machine.n_joints == len(POSE_LABELS))

    def _columns(self) -> None:
        """One column each for the name, where it is from, the joints and the pose; on a
        narrow screen two lines a row: the name over where it is from, each joint over one
        coordinate of the pose, so the pose is on the screen with the joints."""
        self.stacked = self._stack_wanted()
        table = self.query_one("#positions-table", DataTable)
        table.clear(columns=True)
        table.header_height = 2 if self.stacked else 1
        if self.stacked:
            table.add_column(Text("name\nfrom"), key="name")
            for joint, (name, unit) in zip(self.machine.joints, POSE_LABELS, strict=True):
                table.add_column(Text(f"{joint.name} {joint.symbol}\n{name} {unit}",
                                      justify="right"), key=joint.key)
            return
        table.add_column("name", key="name")
        table.add_column("from", key="from")
        for joint in self.machine.joints:
            table.add_column(f"{joint.name} {joint.symbol}", key=joint.key)
        if self.model is not None:
            for name, unit in POSE_LABELS:
                table.add_column(f"{name} {unit}", key=f"pose-{name}")

    def _show(self, book: PositionBook, select: str | None = None) -> None:
        table = self.query_one("#positions-table", DataTable)
        keep = select or self.selected_name()
        table.clear()
        for p in book.positions:
            table.add_row(*self._cells(p), key=p.name, height=2 if self.stacked else 1)
        names = [p.name for p in book.positions]
        if keep in names:
            table.move_cursor(row=names.index(keep))
        self.query_one("#positions-file", Static).update(Text(
            f"{len(book.taught)} taught, kept in {self.path}", "dim"))

    def _cells(self, p: Position) -> list[str | Text]:
        joints = [f"{v:.2f}" for v in p.joints]
        pose = ([f"{v:.1f}" for v in self.model.pose(np.array(p.joints))]
                if self.model is not None else [])
        source = Text(p.source, "dim" if p.taught else "cyan")
        if self.stacked:
            return [Text.assemble((p.name, "bold"), "\n", source),
                    *(Text(f"{q}\n{x}", justify="right") for q, x in zip(joints, pose,
                                                                         strict=True))]
        return [Text(p.name, "bold"), source, *joints, *pose]

    def selected_name(self) -> str | None:
        table = self.query_one("#positions-table", DataTable)
        if not table.row_count:
            return None
        row_key, _ = table.coordinate_to_cell_key(table.cursor_coordinate)
        return row_key.value

    def selected(self) -> Position | None:
        name = self.selected_name()
        return None if name is None else self.book.find(name)

    def go_speed(self) -> float:
        """The speed fraction typed for a go-to (a program's go to takes it); 0.5 while what
        is typed is not one."""
        try:
            speed = self.query_one("#positions-speed", NumberField).value()
        except FieldError:
            return 0.5
        return 0.5 if speed is None else speed

    def refresh_live(self) -> None:
        status = self.status()
        here = self.query_one("#positions-here", LiveText)
        if status is None:
            here.show(Text("waiting for the controller…", "yellow"))
            return
        q = np.array(status.position)
        joints = "  ".join(f"{j.name} {v:.2f}{j.symbol}"
                           for j, v in zip(self.machine.joints, q, strict=True))
        lines = [Text("here  ", "bold") + Text(joints)]
        if self.model is not None:
            pose = self.model.pose(q)
            lines.append(Text("      " + "  ".join(
                f"{name} {v:.1f}{unit if unit == '°' else ' ' + unit}"
                for (name, unit), v in zip(POSE_LABELS, pose, strict=True))))
        if status.estop:
            lines.append(Text("E-STOP latched: release it (^R) before going anywhere",
                              "bold red"))
        here.show(Text("\n").join(lines))

    def _state(self, text: Text) -> None:
        self.query_one("#positions-state", LiveText).show(text)

    # -- the file: every change is read, change, write, in a worker ----------------------------

    @work(thread=True, group="positions-file")
    def _change(self, change: Callable[[PositionBook], PositionBook] | None, done: str = "",
                select: str | None = None) -> None:
        with self._file_lock:
            try:
                book = load_positions(self.path, self.machine)
                if change is not None:
                    book = change(book)
                    save_positions(book, self.path)
            except PositionsError as exc:
                self.post_message(self.Problem(str(exc), in_file=True))
                return
            except ValueError as exc:  # a name taken meanwhile (an edit by hand)
                self.post_message(self.Problem(str(exc), in_file=False))
                return
        self.post_message(self.Loaded(book, done, select, change is not None))

    def on_positions_tab_loaded(self, message: Loaded) -> None:
        self.book = message.book
        self._show(message.book, message.select)
        if message.done:
            self._state(Text(message.done, "green"))
            self.notify(message.done)
        if message.changed:
            self.desk.events.add(LogEntry(time.time(), "position", message.done,
                                          data={"file": str(self.path)}))
        self.post_message(self.Changed(message.book.positions))

    def on_positions_tab_problem(self, message: Problem) -> None:
        fix = (". Nothing was changed: fix the file (or move it away) and press l to read it "
               "again" if message.in_file else "")
        self._state(Text(f"{message.text}{fix}", "bold red"))
        self.notify(f"{message.text}{fix}", severity="error", timeout=8)

    def action_reload(self) -> None:
        self._change(None, f"read {self.path.name} again")

    def _refused(self, what: str) -> bool:
        """Say so and log it if this TUI may not ``what`` (it does not command)."""
        refusal = self.desk.refusal(what)
        if refusal:
            self._state(Text(refusal, "bold red"))
            self.notify(refusal, severity="error", timeout=8)
        return bool(refusal)

    def _write(self, what: str, change: Callable[[PositionBook], PositionBook], done: str,
               select: str | None = None) -> None:
        """``change`` the file, if this TUI still commands (it may have released meanwhile)."""
        if not self._refused(what):
            self._change(change, done, select)

    # -- teach, rename, delete -----------------------------------------------------------------

    def action_teach(self) -> None:
        """Teach where the joints are now, under a name the operator types."""
        if self._refused("teach"):
            return
        status = self.status()
        if status is None:
            self.command("teach", ControlClient.check)
            return
        q = tuple(status.position)
        where = ", ".join(f"{j.name} {v:.2f}{j.symbol}"
                          for j, v in zip(self.machine.joints, q, strict=True))

        def taught(name: str | None) -> None:
            if name is not None:
                name = name.strip()
                self._write("teach", lambda book: book.teach(name, q),
                            f"taught {name}: {where}", name)

        self.app.push_screen(EditValueScreen(
            "Teach the current position", self._free_name(), self.book.check_name,
            f"Where the joints are: {where}. Its name:"), taught)

    def _free_name(self) -> str:
        names = {p.name for p in self.book.positions}
        return next(f"p{n}" for n in range(1, len(names) + 2) if f"p{n}" not in names)

    def action_rename(self) -> None:
        if self._refused("rename"):
            return
        p = self._taught_selected("rename")
        if p is None:
            return

        def renamed(name: str | None) -> None:
            if name is not None:
                name = name.strip()
                self._write("rename", lambda book: book.rename(p.name, name),
                            f"renamed {p.name} to {name}", name)

        self.app.push_screen(EditValueScreen(
            f"Rename {p.name}", p.name, lambda text: self.book.check_name(text, p.name)),
            renamed)

    def action_delete(self) -> None:
        if self._refused("delete"):
            return
        p = self._taught_selected("delete")
        if p is None:
            return

        def deleted(yes: bool | None) -> None:
            if yes:
                self._write("delete", lambda book: book.delete(p.name), f"deleted {p.name}")

        self.app.push_screen(ConfirmScreen(
            f"Delete the position {p.name}?",
            f"It is removed from {self.path}.", "Delete"), deleted)

    def _taught_selected(self, what: str) -> Position | None:
        p = self.selected()
        if p is None:
            self.notify(f"{what}: no position yet: teach one with t", severity="warning")
            return None
        if not p.taught:
            self.notify(f"{what}: {p.name} comes from the machine file "
                        f"({self.machine.path.name}): change it there", severity="warning")
            return None
        return p

    # -- go to ---------------------------------------------------------------------------------

    def action_go_to(self) -> None:
        """Plan a joint-space move to the selected position at the speed fraction typed, show
        it (travel, distance, time) and run that same path once the operator confirms."""
        p = self.selected()
        refusal = self._go_refusal(p)
        client = self.client
        if not refusal:
            assert p is not None and client is not None
            speed = self.query_one("#positions-speed", NumberField).value()
            assert speed is not None
            try:
                plan = form_plans.go_to(self.machine, np.array(client.status().position),
                                        p.joints, speed, dt=client.dt)
            except ValueError as exc:
                refusal = str(exc)
        if refusal:
            self._not_moved(refusal)
            return
        plan = replace(plan, meta={**plan.meta, "position": p.name})

        def answered(yes: bool | None) -> None:
            if yes:
                self._go(plan, p)
            else:
                self._state(Text(f"not moved: the go to {p.name} was cancelled", "yellow"))

        self.app.push_screen(ConfirmScreen(f"Go to {p.name}?", self._go_detail(plan, speed),
                                           f"Go to {p.name}"), answered)

    def _go_detail(self, plan: MovePlan, speed: float) -> str:
        """What the planned path will do: the largest travel of each kind of joint, the tool's
        distance (Unimate), the time."""
        assert plan.path is not None
        start, end = plan.path[0], plan.path[-1]
        travel = np.abs(end - start)
        joints = self.machine.joints
        largest = []
        for unit in dict.fromkeys(j.symbol for j in joints):  # mm, then ° (their order)
            of = [i for i, j in enumerate(joints) if j.symbol == unit]
            i = max(of, key=lambda k: travel[k])
            if travel[i] > 0:
                gap = "" if unit == "°" else " "
                largest.append(f"{joints[i].name} {travel[i]:.1f}{gap}{unit}")
        lines = [f"Largest joint travel: {', '.join(largest) or 'none: already there'}."]
        if self.model is not None:
            distance = float(np.linalg.norm(self.model.pose(end)[:3]
                                            - self.model.pose(start)[:3]))
            lines.append(f"The tool ends {distance:.0f} mm (straight line) from where it is.")
        seconds = (len(plan.path) - 1) * self.desk.dt
        lines.append(f"{seconds:.1f} s at {speed:g} of full speed, then in position within "
                     f"{self.machine.goal_time_s:g} s. Esc is the E-stop.")
        return "\n".join(lines)

    def _go(self, plan: MovePlan, p: Position) -> None:
        """Run the confirmed path, unless something changed while the dialog was open."""
        refusal = self._go_refusal(p)
        client = self.client
        if refusal or client is None:
            self._not_moved(refusal or "the controller is not running")
            return
        try:
            handle = client.run(plan)
        except (ControllerError, ValueError) as exc:
            self._not_moved(str(exc))
            return
        self.handle = handle
        self.query_one("#positions-result", DataTable).display = False
        duration = handle.samples * self.desk.dt
        self._state(Text(f"going to {p.name} at {plan.meta['speed_fraction']:g} of full speed "
                         f"({duration:.1f} s)…", "cyan"))
        self._wait(client, handle, p)

    def _not_moved(self, reason: str) -> None:
        self._state(Text(f"not moved: {reason}", "bold red"))
        self.notify(f"go to: {reason}", severity="error")

    def _go_refusal(self, p: Position | None) -> str:
        """Why a go-to cannot start now, or "" if it can."""
        if p is None:
            return "no position to go to: teach one with t"
        if self.handle is not None:
            return "a go-to is running: wait for it, or hold (^G)"
        status = self.status()
        if status is None:
            return "the controller is not running — " + (self.client_problem
                                                         or "wait for it to start")
        if refusal := self.desk.refusal(f"go to {p.name}"):
            return refusal
        if status.estop:
            return "the E-stop is latched: release it (^R) when it is safe, then go again"
        if status.moving:
            return "a move is running (Moves tab): wait for it, or hold (^G)"
        if not status.homed:
            return ("the encoders are not zeroed: run Initialise (Moves tab) first, so the "
                    "move steers by known positions")
        field = self.query_one("#positions-speed", NumberField)
        try:
            field.check_now()
            field.value()
        except FieldError as exc:
            return str(exc)
        return ""

    @work(thread=True, group="positions-go")
    def _wait(self, client: ControlClient, handle: MoveHandle, p: Position) -> None:
        """Wait for the move to end in position (the controller's settle after the path:
        ``docs/motion.md``), so that "at" means there."""
        result = client.wait(handle)
        times = result.settle.get("settle_s") or ()
        names = ", ".join(j.name for j, t in zip(self.machine.joints, times, strict=False)
                          if t is None)
        self.post_message(self.Arrived(p.name, result, names, result.summaries()))

    def on_positions_tab_arrived(self, message: Arrived) -> None:
        self.handle = None
        result = message.result
        saved = (f"saved as {result.files.stem}" if result.files else
                 result.save_error or "nothing recorded")
        if result.complete:
            self._state(Text(f"at {message.name} · {saved}", "green"))
            self.notify(f"at {message.name}")
        elif result.unsettled:
            self._state(Text(f"near {message.name}: {message.away} not in position "
                             f"{self.machine.goal_time_s:g} s after the move ({result.status}); "
                             f"holding {message.name} · {saved}", "bold yellow"))
            self.notify(f"go to {message.name}: {message.away} not there", severity="warning")
        else:
            self._state(Text(f"go to {message.name}: {result.status} · {saved}", "bold yellow"))
            self.notify(f"go to {message.name}: {result.status}", severity="warning")
        self._result_table(message)
        self.post_message(RunsChanged())

    def _result_table(self, message: Arrived) -> None:
        """How the joints that moved tracked the path and came in position (the Moves tab's
        result rows)."""
        table = self.query_one("#positions-result", DataTable)
        table.clear(columns=True)
        table.add_columns(*summary_columns(message.summaries), SETTLE_COLUMNS[1])
        settle = message.result.settle
        for label, s in message.summaries:
            table.add_row(*summary_cells(label, s), settle_cell(label, settle, self.machine))
        table.display = bool(message.summaries)
