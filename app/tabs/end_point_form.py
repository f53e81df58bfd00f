"""The Moves tab's end point form: an end-effector pose (section 4.3), every inverse solution
inside the limits listed nearest first, and a joint-space ramp to the one picked. The pose
starts as the current one, refreshed from the live position whenever the form is shown,
except a coordinate the operator typed."""

from __future__ import annotations

import numpy as np
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.widgets import Button, DataTable, Static

from app.tabs.move_forms import MoveForm
from app.widgets.fields import NumberCheck, NumberField, seconds_check
from control.motion import form_plans
from control.motion.fields import pose_rule
from control.motion.plan import MovePlan
from hw.machine import Machine
from kinematics.unimate import Unimate2000B

POSE_FIELDS = (("x", "mm", "x"), ("y", "mm", "y"), ("z", "mm", "z"), ("γ", "°", "gamma"),
               ("β", "°", "beta"), ("α", "°", "alpha"))


class EndPointForm(MoveForm):
    KIND = "end_point"
    LABEL = "End point"
    LATER = ("#pose-gamma, #pose-beta, #pose-alpha, #ramp_time", "#pose-current, #ik-state",
             "#ik-solutions")
    HELP = ("End-effector position and X-Y-Z fixed angles (section 4.3); every inverse "
            "solution inside the limits is listed, nearest first — pick another with the "
            "cursor.")

    def __init__(self, machine: Machine, model: Unimate2000B | None) -> None:
        super().__init__(machine, model)
        self.solutions = np.zeros((0, machine.n_joints))
        self.problem = ""

    def fields(self) -> ComposeResult:
        for name, unit, key in POSE_FIELDS:
            yield NumberField(name, NumberCheck.of(pose_rule(name, unit)), placeholder="required",
                              id=f"pose-{key}")
        yield NumberField("ramp time", seconds_check("ramp time", optional=True),
                          placeholder="auto", id="ramp_time")
        yield Button("Pose from the current position", id="pose-current", compact=True)
        yield Static("", id="ik-state")
        yield DataTable(id="ik-solutions", cursor_type="row", zebra_stripes=True)

    def on_mount(self) -> None:
        table = self.query_one("#ik-solutions", DataTable)
        table.add_columns("#", *[f"{j.name} {j.symbol}" for j in self.machine.joints])

    def fill(self, current: np.ndarray) -> None:
        pose = self.model.pose(current)
        for (_, _, key), value in zip(POSE_FIELDS, pose, strict=True):
            self.filled(self.field(f"pose-{key}"), f"{value:.3f}")

    @on(Button.Pressed, "#pose-current")
    def _pose_current(self, event: Button.Pressed) -> None:
        event.stop()
        if not self.here:
            self.notify("the controller has not reported where the joints are yet",
                        severity="warning")
            return
        for f in self.query(NumberField):
            if f.id and f.id.startswith("pose-"):
                f.text = ""  # every coordinate from the position again
        self.fill(np.array(self.here))

    def pose(self) -> np.ndarray:
        return np.array([self.field(f"pose-{key}").value() for _, _, key in POSE_FIELDS])

    def solve(self, current: np.ndarray) -> None:
        """Every solution of the typed pose, nearest ``current`` first, into the table."""
        table = self.query_one("#ik-solutions", DataTable)
        state = self.query_one("#ik-state", Static)
        try:
            self.solutions = form_plans.end_point_solutions(
                self.model, self.pose(), current, ": press the button above")
            self.problem = ""
        except ValueError as exc:  # a FieldError, or no solution
            self.solutions, self.problem = np.zeros((0, 6)), str(exc)
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
        return form_plans.end_point(self.machine, current, self.pose(), self.solutions, k,
                                    self.field("ramp_time").value(), dt=dt)
