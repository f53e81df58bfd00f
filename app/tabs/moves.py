"""Moves: the thesis's movement menus (option.c, function.c; sections 3.5 and 5.2) as forms.

Unimate 2000B: single step, multi-step (all six joints), ramp, sine, end point
and orientation (through the closed-form inverse, every solution shown), path
from a file, via points (joint space, or Cartesian x y z with γ and β held,
section 6.4). Rig: step, multi-step (the sequence of positions and dwell times
of function.c MultiStep), ramp, sine, set pulse (open loop), initialise, path
from a file, via points.

Each field is validated as it is typed; the desired path is previewed before
Run (ctrl+s). A move that starts elsewhere than where the joints are gets an
approach ramp first (the thesis's move() to the start position), left out of
the result summary. The wait for the end runs in a worker; the summary
(overshoot, settling time, steady-state error per joint) appears when it ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.timer import Timer
from textual.widgets import (
    Button,
    ContentSwitcher,
    DataTable,
    Input,
    Label,
    OptionList,
    ProgressBar,
    Select,
    Static,
    Switch,
    TextArea,
)
from textual.widgets.option_list import Option
from textual_plotext import PlotextPlot

from app.desk import Desk
from app.messages import RunsChanged
from app.plotting.run_plot import draw_path
from app.tabs.tab import TabPage
from app.widgets.fields import (
    FieldError,
    JointField,
    NumberCheck,
    NumberField,
    position_check,
    seconds_check,
    set_position_limits,
)
from app.widgets.live_text import LiveText
from control.client import ControlClient, MoveHandle, MoveResult
from control.motion import moves
from control.motion.path_files import PathFileError, PathPoints, read_path, resample
from control.motion.plan import APPROACH_SPEED, MovePlan, moving_joints
from control.motion.robot_model import has_unimate_model
from control.recorder import Run
from hw.machine import Machine
from kinematics import Unreachable

PREVIEW_DELAY_S = 0.25
MAX_SEQUENCE = 10
POSE_FIELDS = (("x", "mm", "x"), ("y", "mm", "y"), ("z", "mm", "z"), ("γ", "°", "gamma"),
               ("β", "°", "beta"), ("α", "°", "alpha"))


class MoveForm(VerticalScroll):
    """One kind of move: fields, and ``plan`` from them and the current position."""

    KIND: ClassVar[str] = ""
    LABEL: ClassVar[str] = ""
    HELP: ClassVar[str] = ""

    def __init__(self, machine: Machine) -> None:
        super().__init__(id=f"form-{self.KIND}", classes="move-form")
        self.machine = machine

    def compose(self) -> ComposeResult:
        yield Static(self.help_text(), classes="form-help")
        yield from self.fields()

    def help_text(self) -> str:
        return self.HELP

    def fields(self) -> ComposeResult:
        yield from ()

    @property
    def tab(self) -> MovesTab:
        return self.query_ancestor(MovesTab)

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        raise NotImplementedError

    def fill(self, current: np.ndarray) -> None:
        """Show the current position as the defaults (placeholders)."""

    def field(self, id: str) -> NumberField:
        return self.query_one(f"#{id}", NumberField)

    def joint(self) -> int:
        return self.query_one(JointField).index if self.machine.n_joints > 1 else 0

    def start_vector(self, current: np.ndarray, j: int) -> np.ndarray:
        start = current.copy()
        value = self.field("start").value()
        if value is not None:
            start[j] = value
        return start

    def joint_fields(self, what: tuple[str, ...]) -> ComposeResult:
        """A joint chooser (unless there is one joint) and position fields for it."""
        m = self.machine
        if m.n_joints > 1:
            yield JointField("joint", m.joints)
        j0 = m.joints[0]
        for name in what:
            optional = name == "start"
            label = "start (blank: here)" if optional else name
            yield NumberField(label, position_check(j0, m, name, optional=optional), id=name)

    @on(Select.Changed)
    def _joint_changed(self, event: Select.Changed) -> None:
        if isinstance(event.select.parent, JointField):
            joint = self.machine.joints[self.joint()]
            for f in self.query(NumberField):
                if f.id in ("start", "target", "end"):
                    set_position_limits(f, joint, self.machine, f.id)
            self.fill(np.asarray(self.tab.current()))


class StepForm(MoveForm):
    KIND = "step"
    LABEL = "Step"
    HELP = ("One joint steps to a target; the others hold (option.c SingleStepInput; the "
            "rig's Step from a start to an end point).")

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "target"))
        yield NumberField("duration (blank: auto)", seconds_check("duration", optional=True),
                          id="duration")

    def fill(self, current: np.ndarray) -> None:
        q = current[self.joint()]
        self.field("start").input.placeholder = f"{q:.2f}"
        if not self.field("target").text:
            self.field("target").input.placeholder = f"{q:.2f}"

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        j = self.joint()
        start = self.start_vector(current, j)
        target = self.field("target").value()
        duration = self.field("duration").value()
        path = moves.step(start, j, target, duration, dt=dt, machine=self.machine)
        joint = self.machine.joints[j]
        return MovePlan("step", f"step {joint.name} to {target:g}{joint.symbol}", path,
                        meta={"joint": joint.name, "start": float(start[j]),
                              "target": float(target)}, moving=(j,))


class MultiStepForm(MoveForm):
    KIND = "multi_step"
    LABEL = "Multi-step"
    HELP = "Every joint steps to its own target at once (option.c MultiStepInput)."

    def fields(self) -> ComposeResult:
        for j, joint in enumerate(self.machine.joints):
            yield NumberField(joint.name, position_check(joint, self.machine, "target"),
                              id=f"target{j}")
        yield NumberField("duration (blank: auto)", seconds_check("duration", optional=True),
                          id="duration")
        yield Button("Targets from the current position", id="from-current")

    def fill(self, current: np.ndarray) -> None:
        for j in range(self.machine.n_joints):
            f = self.field(f"target{j}")
            f.input.placeholder = f"{current[j]:.2f}"

    @on(Button.Pressed, "#from-current")
    def _from_current(self, event: Button.Pressed) -> None:
        event.stop()
        current = self.tab.current()
        for j in range(self.machine.n_joints):
            self.field(f"target{j}").text = f"{current[j]:.2f}"

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        targets = [self.field(f"target{j}").value() for j in range(self.machine.n_joints)]
        duration = self.field("duration").value()
        path = moves.multi_step(current, targets, duration, dt=dt, machine=self.machine)
        return MovePlan("multi_step", "multi-step", path,
                        meta={"targets": [float(t) for t in targets]},
                        moving=moving_joints(path))


class SequenceForm(MoveForm):
    KIND = "multi_step"
    LABEL = "Multi-step"
    HELP = ("Step to each position in turn and stay there for its dwell time "
            "(function.c MultiStep).")

    def fields(self) -> ComposeResult:
        joint = self.machine.joints[0]
        yield NumberField("steps", NumberCheck("number of steps", "", 1, MAX_SEQUENCE,
                                               integer=True), "3", id="count")
        for i in range(MAX_SEQUENCE):
            with Horizontal(classes="sequence-row", id=f"row{i}"):
                yield NumberField(f"{i + 1}. position", position_check(joint, self.machine,
                                                                      f"step {i + 1} position"),
                                  id=f"pos{i}")
                yield NumberField("dwell", seconds_check(f"step {i + 1} dwell"), "2",
                                  id=f"dwell{i}")

    def on_mount(self) -> None:
        self._rows(3)

    @on(Input.Changed, "#count Input")
    def _count_changed(self, event: Input.Changed) -> None:
        try:
            count = int(self.field("count").check.parse(event.value) or 1)
        except FieldError:
            return
        self._rows(count)

    def _rows(self, count: int) -> None:
        for i in range(MAX_SEQUENCE):
            self.query_one(f"#row{i}").display = i < count

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        count = int(self.field("count").value() or 1)
        steps = [(self.field(f"pos{i}").value(), self.field(f"dwell{i}").value())
                 for i in range(count)]
        path = moves.rig_sequence(current, steps, dt=dt, machine=self.machine)
        return MovePlan("multi_step", f"sequence of {count} steps", path,
                        meta={"steps": [[float(p), float(d)] for p, d in steps]},
                        moving=(0,))


class StartEndForm(MoveForm):
    """A one-joint move between a start (blank: where the joint is) and an end field."""

    def fill(self, current: np.ndarray) -> None:
        self.field("start").input.placeholder = f"{current[self.joint()]:.2f}"

    def ends(self, current: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """The joint, and the start and end joint vectors (the others stay where they are)."""
        j = self.joint()
        start = self.start_vector(current, j)
        end = start.copy()
        end[j] = self.field("end").value()
        return j, start, end


class RampForm(StartEndForm):
    KIND = "ramp"
    LABEL = "Ramp"
    HELP = "From a start to an end position at constant speed, then hold (function.c RampInput)."

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "end"))
        yield NumberField("ramp time", seconds_check("ramp time"), "2", id="ramp_time")
        yield NumberField("total (blank: auto)", seconds_check("total duration", optional=True),
                          id="total")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        j, start, end = self.ends(current)
        ramp_time = self.field("ramp_time").value()
        path = moves.ramp(start, end, ramp_time, self.field("total").value(), dt=dt,
                          machine=self.machine)
        joint = self.machine.joints[j]
        return MovePlan("ramp", f"ramp {joint.name} to {end[j]:g}{joint.symbol}", path,
                        meta={"joint": joint.name, "start": float(start[j]),
                              "end": float(end[j]), "ramp_time": ramp_time},
                        moving=(j,))


class SineForm(StartEndForm):
    KIND = "sine"
    LABEL = "Sine"
    HELP = ("start + (end − start)/2 · (1 − cos 2πt/T): at the end at T/2, back at T "
            "(function.c Sinewave).")

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "end"))
        yield NumberField("period T", seconds_check("period"), "4", id="period")
        yield NumberField("duration", seconds_check("duration"), "8", id="duration")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        j, start, end = self.ends(current)
        period, duration = self.field("period").value(), self.field("duration").value()
        path = moves.sine(start, end, period, duration, dt=dt, machine=self.machine)
        joint = self.machine.joints[j]
        return MovePlan("sine", f"sine {joint.name} {start[j]:g}↔{end[j]:g}{joint.symbol}",
                        path, meta={"joint": joint.name, "start": float(start[j]),
                                    "end": float(end[j]), "period": period,
                                    "duration": duration},
                        moving=(j,))


class EndPointForm(MoveForm):
    KIND = "end_point"
    LABEL = "End point"
    HELP = ("End-effector position and X-Y-Z fixed angles (section 4.3); every inverse "
            "solution inside the limits is listed, nearest first — pick another with the "
            "cursor.")

    def __init__(self, machine: Machine) -> None:
        super().__init__(machine)
        self.solutions = np.zeros((0, machine.n_joints))
        self.problem = ""

    def fields(self) -> ComposeResult:
        for name, unit, key in POSE_FIELDS:
            yield NumberField(name, NumberCheck(name, unit), id=f"pose-{key}")
        yield NumberField("ramp time (blank: auto)", seconds_check("ramp time", optional=True),
                          id="ramp_time")
        yield Button("Pose from the current position", id="pose-current")
        yield Static("", id="ik-state")
        yield DataTable(id="ik-solutions", cursor_type="row", zebra_stripes=True)

    def on_mount(self) -> None:
        table = self.query_one("#ik-solutions", DataTable)
        table.add_columns("#", *[f"{j.name} {j.symbol}" for j in self.machine.joints])

    def fill(self, current: np.ndarray) -> None:
        pose = self.tab.model.pose(current)
        for (_, _, key), value in zip(POSE_FIELDS, pose, strict=True):
            f = self.field(f"pose-{key}")
            f.input.placeholder = f"{value:.3f}"
            if not f.text:
                f.text = f"{value:.3f}"

    @on(Button.Pressed, "#pose-current")
    def _pose_current(self, event: Button.Pressed) -> None:
        event.stop()
        pose = self.tab.model.pose(self.tab.current())
        for (_, _, key), value in zip(POSE_FIELDS, pose, strict=True):
            self.field(f"pose-{key}").text = f"{value:.3f}"

    def pose(self) -> np.ndarray:
        return np.array([self.field(f"pose-{key}").value() for _, _, key in POSE_FIELDS])

    def solve(self, current: np.ndarray) -> None:
        """Every solution of the typed pose, nearest ``current`` first, into the table."""
        table = self.query_one("#ik-solutions", DataTable)
        state = self.query_one("#ik-state", Static)
        try:
            pose = self.pose()
            self.solutions = self.tab.model.inverse(pose, near=current)
            self.problem = ""
        except FieldError as exc:
            self.solutions, self.problem = np.zeros((0, 6)), str(exc)
        except Unreachable as exc:
            self.solutions = np.zeros((0, 6))
            self.problem = (f"unreachable: {exc}. Change the position or the angles "
                            "(the current pose is always reachable: press the button above).")
        chosen = table.cursor_row if table.row_count == len(self.solutions) else 0
        table.clear()
        for k, q in enumerate(self.solutions):
            table.add_row(str(k + 1), *[f"{v:.2f}" for v in q], key=str(k))
        if len(self.solutions):
            table.move_cursor(row=min(chosen, len(self.solutions) - 1))
            state.update(Text(f"{len(self.solutions)} solution(s) inside the limits; "
                              "row 1 is nearest the current position", "green"))
        else:
            state.update(Text(self.problem, "bold red"))

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        self.solve(current)
        if not len(self.solutions):
            raise ValueError(self.problem or "no solution")
        k = self.query_one("#ik-solutions", DataTable).cursor_row
        q = self.solutions[max(0, min(k, len(self.solutions) - 1))]
        ramp_time = self.field("ramp_time").value()
        if ramp_time is None:
            speeds = np.array([APPROACH_SPEED * j.max_speed for j in self.machine.joints])
            ramp_time = max(0.5, float(np.max(np.abs(q - current) / speeds)))
        path = moves.ramp(current, q, ramp_time, dt=dt, machine=self.machine)
        return MovePlan("end_point", f"end point, solution {k + 1}", path,
                        meta={"pose": self.pose().tolist(), "solution": q.tolist(),
                              "solution_index": int(k), "ramp_time": ramp_time},
                        moving=moving_joints(path),
                        note=f"joint-space ramp to solution {k + 1} in {ramp_time:.2f} s")


class PathFileForm(MoveForm):
    KIND = "path"
    LABEL = "Path file"

    def help_text(self) -> str:
        if self.machine.n_joints == 1:
            return ("A time/position TSV as the thesis's data files (time<TAB>position per "
                    "line), or a CSV with a header t,Ram. Seconds and mm.")
        return ("A CSV with a header of joint names (t,In/Out,Rotate,…; a joint left out "
                "stays where it is) or a TSV of time then six positions. Seconds, mm, deg.")

    @dataclass
    class Loaded(Message, bubble=False):
        """The file ``source`` was read (from the loading worker)."""

        points: PathPoints
        source: str

    @dataclass
    class Refused(Message, bubble=False):
        """The file could not be used; ``problem`` names the line (from the loading worker)."""

        problem: str

    def __init__(self, machine: Machine) -> None:
        super().__init__(machine)
        self.points: PathPoints | None = None
        self.loaded_from = ""

    def fields(self) -> ComposeResult:
        with Horizontal(classes="field"):
            yield Label("file", classes="field-label")
            yield Input(placeholder="path.csv or path.tsv", id="path-file", compact=True)
        yield Static("", id="path-state")

    @on(Input.Submitted, "#path-file")
    def _submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.load(event.value, np.asarray(self.tab.current()))

    @work(thread=True, exclusive=True, group="path-file")
    def load(self, text: str, current: np.ndarray) -> None:
        try:
            points = read_path(text, self.machine, tuple(current))
        except PathFileError as exc:
            self.post_message(self.Refused(str(exc)))
            return
        self.post_message(self.Loaded(points, text))

    def on_path_file_form_refused(self, message: Refused) -> None:
        self.points = None
        self.loaded_from = ""
        self.query_one("#path-state", Static).update(Text(
            f"{message.problem}. Fix the file and press Enter in the field again.", "bold red"))

    def on_path_file_form_loaded(self, message: Loaded) -> None:
        points = self.points = message.points
        self.loaded_from = message.source
        self.query_one("#path-state", Static).update(Text(
            f"{len(points.t)} points over {points.duration:g} s from {message.source}", "green"))
        self.tab.schedule_preview()

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        wanted = self.query_one("#path-file", Input).value
        if self.points is None or wanted != self.loaded_from:
            raise ValueError("load the file first: type its path and press Enter")
        path = resample(self.points, dt)
        return MovePlan("path", f"path {Path(self.loaded_from).name}", path,
                        meta={"file": str(Path(self.loaded_from).expanduser().resolve())},
                        moving=moving_joints(path))


class ViaPointsForm(MoveForm):
    KIND = "via_points"
    LABEL = "Via points"
    HELP = ("A smooth path from here through points, one per line: every joint's position "
            "(joint space, section 6.4's via points), or with Cartesian on the tool's x y z in "
            "mm with γ and β held (section 6.4). Numbers separated by spaces or commas.")

    def fields(self) -> ComposeResult:
        if self.cartesian_allowed:
            with Horizontal(classes="field"):
                yield Label("Cartesian (x y z)", classes="field-label")
                yield Switch(value=False, id="via-cartesian")
        yield NumberField("speed fraction", NumberCheck("speed fraction", "", 0.0, 1.0,
                                                        strict_low=True), "0.5", id="speed")
        yield Label("points", classes="field-label")
        yield TextArea(id="via-points", soft_wrap=False, show_line_numbers=True)
        yield Button("Add the current position", id="via-add")

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
        self.tab.schedule_preview()

    def on_switch_changed(self, event: Switch.Changed) -> None:
        event.stop()
        self.tab.schedule_preview()

    @on(Button.Pressed, "#via-add")
    def _add_current(self, event: Button.Pressed) -> None:
        event.stop()
        current = self.tab.current()
        row = self.tab.model.pose(current)[:3] if self.cartesian else current
        area = self.query_one("#via-points", TextArea)
        text = area.text.rstrip("\n")
        area.text = (text + "\n" if text else "") + " ".join(f"{v:.2f}" for v in row)

    def points(self) -> np.ndarray:
        """The typed points ``(M, J)`` or ``(M, 3)``; ValueError naming the line and the fix."""
        width = 3 if self.cartesian else self.machine.n_joints
        what = "x y z (mm)" if self.cartesian else f"{width} joint positions"
        rows = []
        for n, line in enumerate(self.query_one("#via-points", TextArea).text.splitlines(), 1):
            parts = line.replace(",", " ").split()
            if not parts:
                continue
            try:
                row = [float(p) for p in parts]
            except ValueError:
                raise ValueError(f"point line {n}: {line.strip()!r} is not numbers; "
                                 f"type {what}") from None
            if len(row) != width or not all(math.isfinite(v) for v in row):
                raise ValueError(f"point line {n}: {len(row)} numbers; type {what}")
            rows.append(row)
        if not rows:
            raise ValueError(f"type at least one point, one per line: {what}")
        return np.array(rows)

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        from control.motion.cartesian import cartesian_path  # scipy's splines: loaded on first use
        from control.motion.trajectory import via_path

        points = self.points()
        fraction = self.field("speed").value()
        meta = {"points": points.tolist(), "speed_fraction": fraction}
        if self.cartesian:
            path = cartesian_path(current, points, self.machine, dt=dt,
                                  speed_fraction=fraction).q
            return MovePlan("cartesian", f"Cartesian path through {len(points)} points", path,
                            meta=meta, moving=moving_joints(path))
        path = via_path(np.vstack([current, points]), self.machine, dt=dt,
                        speed_fraction=fraction).q
        return MovePlan("via_points", f"path through {len(points)} via points", path,
                        meta=meta, moving=moving_joints(path))


class PulseForm(MoveForm):
    KIND = "set_pulse"
    LABEL = "Set pulse"
    HELP = ("Open loop: a constant duty for a time, recorded (function.c SetPulse). Positive "
            "drives the ram up. The controller stops it at a limit.")

    def fields(self) -> ComposeResult:
        yield NumberField("duty", NumberCheck("duty", " %", -100, 100, nonzero=True), "20",
                          id="duty")
        yield NumberField("duration", seconds_check("duration", high=60), "1", id="duration")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        duty, duration = self.field("duty").value(), self.field("duration").value()
        samples = round(duration / dt) + 1
        profile = np.zeros((samples, self.machine.n_joints))
        profile[:, 0] = duty
        return MovePlan("set_pulse", f"pulse {duty:g} % for {duration:g} s", profile=profile,
                        meta={"duty": duty, "duration": duration}, moving=(0,))


class InitialiseForm(MoveForm):
    KIND = "initialise"
    LABEL = "Initialise"
    HELP = ("Drive the ram down at 20 % until it rests on the bottom stop, then zero the "
            "encoder (section 3.5; function.c Initialise). Needed before any closed-loop move "
            "on the rig.")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return MovePlan("initialise", "initialise")


def forms_for(machine: Machine) -> list[type[MoveForm]]:
    if machine.n_joints == 1:
        return [StepForm, SequenceForm, RampForm, SineForm, PulseForm, InitialiseForm,
                PathFileForm, ViaPointsForm]
    kinds: list[type[MoveForm]] = [StepForm, MultiStepForm, RampForm, SineForm]
    if has_unimate_model(machine):
        kinds.append(EndPointForm)
    return [*kinds, PathFileForm, ViaPointsForm]


class MovesTab(TabPage):
    """Choose a move, fill it in, preview it, run it, read its result."""

    REFRESH_HZ = 10.0
    TITLE = "Moves"

    class HoldRequested(Message):
        """Abort was pressed: abort the move and hold every joint where it is."""

    @dataclass
    class RunUnsaved(Message):
        """A move's run could not be saved: keep it, so it can be saved elsewhere."""

        run: Run

    @dataclass
    class MoveFinished(Message, bubble=False):
        """The move ended (from the waiting worker): its result and summary rows."""

        result: MoveResult
        plan: MovePlan
        summaries: list[tuple[str, moves.StepSummary]]

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.handle: MoveHandle | None = None
        self.plan_running: MovePlan | None = None
        self.initialising = False
        self.last_result: MoveResult | None = None
        self._preview_timer: Timer | None = None
        self._filled = False

    def compose(self) -> ComposeResult:
        kinds = forms_for(self.machine)
        with Horizontal():
            with Vertical(id="moves-left"):
                yield OptionList(*[Option(k.LABEL, id=k.__name__) for k in kinds],
                                 id="move-kinds")
                yield Static(id="move-error")
                with Horizontal(id="move-buttons"):
                    yield Button("Run ^S", id="move-run", variant="success")
                    yield Button("Abort ^G", id="move-abort", variant="error")
            with ContentSwitcher(id="move-forms", initial=f"form-{kinds[0].KIND}"):
                for kind in kinds:
                    yield kind(self.machine)
            with Vertical(id="moves-right"):
                yield Static(id="move-preview-title")
                yield PlotextPlot(id="move-preview")
                yield ProgressBar(total=100, show_eta=False, id="move-progress")
                yield LiveText(id="move-state")
                yield DataTable(id="move-result", cursor_type="none", zebra_stripes=True)

    def on_mount(self) -> None:
        self.query_one("#move-result", DataTable).add_columns(
            "joint", "step", "overshoot", "rise s", "settle s", "steady error", "max |e|")
        self._state(Text("no move yet", "dim"))

    # -- plumbing ---------------------------------------------------------------------------

    @property
    def form(self) -> MoveForm:
        switcher = self.query_one("#move-forms", ContentSwitcher)
        return self.query_one(f"#{switcher.current}", MoveForm)

    def current(self) -> np.ndarray:
        status = self.status()
        if status is None:
            return np.array([(j.lower + j.upper) / 2 for j in self.machine.joints])
        return np.array(status.position)

    def focus_main(self) -> None:
        self.query_one("#move-kinds", OptionList).focus()

    def shown(self) -> None:
        super().shown()
        self._fill_forms()
        self.schedule_preview()

    def client_ready(self, client: ControlClient) -> None:
        super().client_ready(client)
        if self.visible_now:
            self._fill_forms()

    def _fill_forms(self) -> None:
        if self._filled or self.status() is None:
            return
        self._filled = True
        current = self.current()
        for form in self.query(MoveForm):
            form.fill(current)

    def on_option_list_option_highlighted(self, event: OptionList.OptionHighlighted) -> None:
        event.stop()
        kind = next(k for k in forms_for(self.machine) if k.__name__ == event.option.id)
        self.query_one("#move-forms", ContentSwitcher).current = f"form-{kind.KIND}"
        self.query_one("#move-error", Static).update("")
        self.form.fill(self.current())
        self.schedule_preview()

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        event.stop()
        inputs = [w for w in self.form.query("Input, Select") if w.focusable]
        if inputs:
            inputs[0].focus()

    def on_input_changed(self, event: Input.Changed) -> None:
        self.schedule_preview()

    def on_select_changed(self, event: Select.Changed) -> None:
        self.schedule_preview()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.data_table.id == "ik-solutions":
            self.schedule_preview()

    def schedule_preview(self) -> None:
        if self._preview_timer is not None:
            self._preview_timer.stop()
        self._preview_timer = self.set_timer(PREVIEW_DELAY_S, self.preview)

    # -- preview ----------------------------------------------------------------------------

    def make_plan(self) -> MovePlan:
        form = self.form
        current = self.current()
        if isinstance(form, EndPointForm):
            form.solve(current)
        dt = self.machine.sample_time_s
        return form.plan(current, dt).approached(current, self.machine, dt)

    def preview(self) -> None:
        title = self.query_one("#move-preview-title", Static)
        plot = self.query_one("#move-preview", PlotextPlot)
        try:
            plan = self.make_plan()
        except (FieldError, ValueError) as exc:
            title.update(Text(str(exc), "yellow"))
            plot.plt.clear_figure()
            plot.refresh()
            return
        dt = self.machine.sample_time_s
        if plan.path is not None:
            t = np.arange(plan.samples) * dt
            names = [j.name for j in self.machine.joints]
            units = [j.symbol for j in self.machine.joints]
            draw_path(plot.plt, t, plan.path, names, units, plan.moving,
                      max(20, plot.size.width), plan.title)
            summary = f"{plan.title}: {plan.samples} samples, {t[-1]:.2f} s"
        elif plan.profile is not None:
            t = np.arange(plan.samples) * dt
            draw_path(plot.plt, t, plan.profile, ["duty"], ["%"], [0],
                      max(20, plot.size.width), plan.title)
            summary = f"{plan.title}: open loop, {plan.samples} samples"
        else:
            plot.plt.clear_figure()
            summary = "initialise: drives down to the bottom stop, then zeroes the encoder"
        plot.refresh()
        note = f" · {plan.note}" if plan.note else ""
        approach = (f" · includes a {plan.approach * dt:.2f} s approach to the start"
                    if plan.approach else "")
        title.update(Text.assemble(("preview  ", "bold"), summary, approach, note))

    # -- running ----------------------------------------------------------------------------

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "move-run":
            event.stop()
            self.action_run()
        elif event.button.id == "move-abort":
            event.stop()
            self.post_message(self.HoldRequested())

    def action_run(self) -> None:
        error = self.query_one("#move-error", Static)
        if self.handle is not None or self.initialising:
            error.update(Text("a move is running: wait for it, or abort it with ^G", "yellow"))
            return
        for f in self.form.query(NumberField):
            if f.display and (f.parent is None or f.parent.display):
                f.check_now()
        try:
            plan = self.make_plan()
        except (FieldError, ValueError) as exc:
            error.update(Text(f"{exc}", "bold red"))
            self.notify(f"not run: {exc}", severity="error")
            return
        error.update("")
        client = self.client
        if client is None:
            self.command("run", ControlClient.check)
            return
        if plan.kind == "initialise":
            if self.command("initialise", ControlClient.initialise):
                self.initialising = True
                self._state(Text("initialising: driving down to the bottom stop…", "cyan"))
            return
        try:
            handle = client.run(plan)
        except Exception as exc:  # ControllerError, ValueError from the client's checks
            error.update(Text(f"{exc}", "bold red"))
            self.notify(f"not run: {exc}", severity="error")
            return
        self.handle, self.plan_running = handle, plan
        self.query_one("#move-result", DataTable).clear()
        self._state(Text(f"running {plan.title}…", "cyan"))
        self._wait(client, handle, plan)

    @work(thread=True, group="move-wait")
    def _wait(self, client: ControlClient, handle: MoveHandle, plan: MovePlan) -> None:
        result = client.wait(handle)
        self.post_message(self.MoveFinished(result, plan, result.summaries()))

    def on_moves_tab_move_finished(self, message: MoveFinished) -> None:
        result, plan = message.result, message.plan
        self.handle = None
        self.plan_running = None
        self.last_result = result
        saved = (f"saved as {result.files.stem}" if result.files else
                 result.save_error or "nothing recorded")
        style = "green" if result.complete else "bold yellow"
        self._state(Text(f"{plan.title}: {result.status} · {saved}", style))
        bar = self.query_one("#move-progress", ProgressBar)
        if result.complete:
            bar.update(progress=bar.total)
        self._result_table(message.summaries)
        if result.files is None and result.run.samples:
            self.post_message(self.RunUnsaved(result.run))
        self.form.fill(self.current())  # "here" has moved
        self.schedule_preview()
        self.post_message(RunsChanged())
        severity = "information" if result.complete else "warning"
        self.notify(f"{plan.title}: {result.status}", severity=severity)

    def initialised(self, status: str) -> None:
        self.initialising = False
        self._state(Text(f"initialise: {status}", "green" if "complete" in status else "yellow"))

    def _result_table(self, summaries: list[tuple[str, moves.StepSummary]]) -> None:
        table = self.query_one("#move-result", DataTable)
        table.clear()
        for label, s in summaries:
            u = " " + ("°" if s.unit == "deg" else s.unit)
            table.add_row(
                label, f"{s.step:+.2f}{u}", f"{s.overshoot:.2f}{u} ({s.overshoot_pct:.1f} %)",
                _seconds(s.rise_time_s), _seconds(s.settling_time_s),
                f"{s.steady_state_error:+.3f}{u}", f"{s.max_abs_error:.3f}{u}")

    def _state(self, text: Text) -> None:
        self.query_one("#move-state", LiveText).show(text)

    def refresh_live(self) -> None:
        status = self.status()
        bar = self.query_one("#move-progress", ProgressBar)
        handle = self.handle
        if status is None or handle is None:
            return
        if status.move_id == handle.move_id and status.move_total:
            bar.update(total=status.move_total, progress=status.move_done)
            dt = self.machine.sample_time_s
            self._state(Text(f"running {handle.kind}: {status.move_done * dt:.2f} / "
                             f"{status.move_total * dt:.2f} s", "cyan"))


def _seconds(value: float | None) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.3f}"
