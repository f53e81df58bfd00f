"""The Moves tab's path forms: a path from a file (the thesis's time/position data files, or
a CSV of joint columns), and a smooth path through via points, in joint space or on the
tool's x y z with γ and β held (section 6.4)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.message import Message
from textual.widgets import Button, Input, Label, Select, Static, Switch, TextArea

from app.tabs.move_forms import MoveForm, mid_range
from app.widgets.fields import NumberCheck, NumberField
from app.widgets.typed import FieldInput, FieldTextArea
from control.motion import form_plans
from control.motion.fields import VIA_SPEED, fraction_rule
from control.motion.path_files import PathFileError, PathPoints, read_path
from control.motion.plan import MovePlan
from control.motion.positions import Position
from control.motion.robot_model import has_unimate_model
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


class PathFileForm(MoveForm):
    KIND = "path"
    LABEL = "Path file"

    def help_text(self) -> str:
        again = (" Or a saved run (its .json, .csv.gz or .tsv.gz): its desired path plays "
                 "again, at its own timing, as the move it was.")
        if self.machine.n_joints == 1:
            return ("A time/position TSV as the thesis's data files (time<TAB>position per "
                    "line), or a CSV with a header t,Ram. Seconds and mm." + again)
        return ("A CSV with a header of joint names (t,In/Out,Rotate,…; a joint left out "
                "stays where it is) or a TSV of time then six positions. Seconds, mm, deg."
                + again)

    @dataclass
    class Loaded(Message, bubble=False):
        """The file ``source`` was read (from the loading worker)."""

        points: PathPoints
        source: str

    @dataclass
    class Refused(Message, bubble=False):
        """The file could not be used; ``problem`` names the line (from the loading worker)."""

        problem: str

    def __init__(self, machine: Machine, model: Unimate2000B | None) -> None:
        super().__init__(machine, model)
        self.points: PathPoints | None = None
        self.loaded_from = ""
        # what a typed path names, or ValueError: the Moves tab hands down its desk's
        # ``typed_path`` (a TUI that does not command previews only the data directory's files)
        self.typed_path: Callable[[str, str], Path] = lambda text, what: Path(text)

    def fields(self) -> ComposeResult:
        with Horizontal(classes="field"):
            yield Label("file", classes="field-label")
            yield FieldInput(placeholder="path.csv, path.tsv or a run's .json", id="path-file",
                             compact=True)
        yield Static("", id="path-state")

    @on(Input.Submitted, "#path-file")
    def _submitted(self, event: Input.Submitted) -> None:
        event.stop()
        try:
            path = self.typed_path(event.value, "read the path file")
        except ValueError as exc:
            self.on_path_file_form_refused(self.Refused(str(exc)))
            return
        # the joints the file leaves out are checked where they are now, and played from
        # where they are when the move runs (``plan``)
        self.load(path, event.value,
                  np.array(self.here) if self.here else mid_range(self.machine))

    @work(thread=True, exclusive=True, group="path-file")
    def load(self, path: Path, text: str, current: np.ndarray) -> None:
        try:
            points = read_path(path, self.machine, tuple(current))
        except PathFileError as exc:
            self.post_message(self.Refused(f"{exc}. Fix the file and press Enter in the field "
                                           "again."))
            return
        self.post_message(self.Loaded(points, text))

    def on_path_file_form_refused(self, message: Refused) -> None:
        self.points = None
        self.loaded_from = ""
        self.query_one("#path-state", Static).update(Text(message.problem, "bold red"))

    def on_path_file_form_loaded(self, message: Loaded) -> None:
        points = self.points = message.points
        self.loaded_from = message.source
        what = (f"{points.run}: {len(points.t)} samples over {points.duration:g} s, as a "
                f"{points.kind}" if points.run else
                f"{len(points.t)} points over {points.duration:g} s from {message.source}")
        self.query_one("#path-state", Static).update(Text(what, "green"))
        self.post_message(self.PreviewWanted())

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        wanted = self.query_one("#path-file", Input).value
        if self.points is None or wanted != self.loaded_from:
            raise ValueError("load the file first: type its path and press Enter")
        return form_plans.path_file(self.machine, current, self.points, self.loaded_from, dt=dt)


class ViaPointsForm(MoveForm):
    KIND = "via_points"
    LABEL = "Via points"
    HELP = ("A smooth path from here through points, one per line: every joint's position "
            "(joint space, section 6.4's via points), or with Cartesian on the tool's x y z in "
            "mm with γ and β held (section 6.4). Numbers separated by spaces or commas.")
    named: tuple[Position, ...] = ()  # home, park and the taught positions, as offered

    def fields(self) -> ComposeResult:
        if self.cartesian_allowed:
            with Horizontal(classes="field"):
                yield Label("Cartesian (x y z)", classes="field-label")
                yield Switch(value=False, id="via-cartesian")
        yield NumberField("speed fraction", NumberCheck.of(fraction_rule("speed fraction")),
                          f"{VIA_SPEED:g}", id="speed")
        yield Label("points", classes="field-label")
        yield FieldTextArea(id="via-points", soft_wrap=False, show_line_numbers=True)
        yield Button("Add the current position", id="via-add", compact=True)
        with Horizontal(classes="field"):
            yield Select[int]([], prompt="a named position", id="via-named", compact=True,
                              classes="field-select")
            yield Button("Add it", id="via-add-named", compact=True)

    def offer(self, positions: tuple[Position, ...]) -> None:
        """The named positions (home, park, taught: the Positions tab's) the points may use."""
        self.named = positions
        self.query_one("#via-named", Select).set_options(
            (p.name, i) for i, p in enumerate(positions))

    @property
    def cartesian_allowed(self) -> bool:
        return has_unimate_model(self.machine)

    @property
    def cartesian(self) -> bool:
        return self.cartesian_allowed and self.query_one("#via-cartesian", Switch).value

    def help_text(self) -> str:
        names = " ".join(j.name for j in self.machine.joints)
        return f"{self.HELP} Joint order: {names}."

    def on_text_area_changed(self, event: TextArea.Changed) -> None:
        self.post_message(self.PreviewWanted())

    def on_switch_changed(self, event: Switch.Changed) -> None:
        event.stop()
        self.post_message(self.PreviewWanted())

    @on(Button.Pressed, "#via-add")
    def _add_current(self, event: Button.Pressed) -> None:
        event.stop()
        if not self.here:
            self.notify("the controller has not reported where the joints are yet",
                        severity="warning")
            return
        self.append(np.array(self.here))

    @on(Button.Pressed, "#via-add-named")
    def _add_named(self, event: Button.Pressed) -> None:
        event.stop()
        chosen = self.query_one("#via-named", Select).value
        if not isinstance(chosen, int):
            self.notify("choose a named position first (teach them on the Positions tab)",
                        severity="warning")
            return
        self.append(np.array(self.named[chosen].joints))

    def append(self, q: np.ndarray) -> None:
        """Add the joints ``q (J,)`` as a point (their x y z when Cartesian)."""
        row = self.model.pose(q)[:3] if self.cartesian else q
        area = self.query_one("#via-points", TextArea)
        text = area.text.rstrip("\n")
        area.text = (text + "\n" if text else "") + " ".join(f"{v:.3f}" for v in row)

    def points(self) -> np.ndarray:
        """The typed points ``(M, J)`` or ``(M, 3)``; ValueError naming the line and the fix."""
        return form_plans.via_point_rows(self.query_one("#via-points", TextArea).text,
                                         self.machine, self.cartesian)

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return form_plans.via_points(self.machine, current, self.points(),
                                     self.field("speed").value(), self.cartesian, dt=dt)
