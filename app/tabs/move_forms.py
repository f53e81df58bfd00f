"""The Moves tab's forms: the thesis's movement menus (option.c, function.c; sections 3.5 and
5.2). A form validates its fields as they are typed and turns them into a ``MovePlan``
(``control.motion.plan``) from where the joints are.

Here the joint-space moves: single step, multi-step (all six joints; on the rig, the
sequence of positions and dwell times of function.c MultiStep), ramp, sine, and the rig's
set pulse (open loop) and initialise. The end point form is in ``end_point_form``, the path
file and via points forms in ``path_forms``.

Nothing a form shows may be stale. A field left blank means "where the joint is" at the
moment the move is planned, and its placeholder says so with the live position
(``here``); a required field's placeholder says "required", never a number that looks
typed. A value a form fills in from the position (the end point's pose, the multi-step's
"targets from the current position") is refreshed from the live position whenever the
form is shown (``fill``), unless the operator has typed over it since.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.reactive import reactive
from textual.widgets import Button, Input, Select, Static

from app.widgets.fields import (
    FieldError,
    JointField,
    NumberCheck,
    NumberField,
    position_check,
    seconds_check,
    set_position_limits,
)
from app.widgets.staged import Staged
from control.motion import form_plans
from control.motion.fields import (
    DWELL_S,
    MAX_SEQUENCE,
    PULSE_DUTY_PCT,
    PULSE_MAX_S,
    PULSE_S,
    RAMP_TIME_S,
    SEQUENCE_STEPS,
    SINE_DURATION_S,
    SINE_PERIOD_S,
    count_rule,
    duty_rule,
)
from control.motion.moves import SETTLE_TAIL_S
from control.motion.plan import MovePlan
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


def mid_range(machine: Machine) -> np.ndarray:
    """``(J,)``: the middle of every joint's range, where a form takes the joints to be
    before the controller reports."""
    return np.array([(j.lower + j.upper) / 2 for j in machine.joints])


class MoveForm(Staged, VerticalScroll):
    """One kind of move: fields, and ``plan`` from them and the current position.

    ``here`` is where the joints are, set by the tab as the controller reports it (empty
    until then); a form reads it, never the tab. Placeholders follow it (``show_here``).
    A big form draws its ``LATER`` parts after the rest the first time it is shown (``Staged``).
    """

    KIND: ClassVar[str] = ""
    LABEL: ClassVar[str] = ""
    HELP: ClassVar[str] = ""

    here: reactive[tuple[float, ...]] = reactive((), init=False)

    class PreviewWanted(Message):
        """The form's plan may have changed (not by a typed field): preview it again."""

    def __init__(self, machine: Machine, model: Unimate2000B | None) -> None:
        super().__init__(id=f"form-{self.KIND}", classes="move-form")
        self.machine = machine
        self.model = model
        self._filled: dict[str, str] = {}  # field id: the text ``fill`` last put there

    def compose(self) -> ComposeResult:
        yield Static(self.help_text(), classes="form-help")
        yield from self.fields()

    def help_text(self) -> str:
        return self.HELP

    def fields(self) -> ComposeResult:
        yield from ()

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        raise NotImplementedError

    def fill(self, current: np.ndarray) -> None:
        """The form is shown: refresh what it filled in from the position (``filled``)."""

    def watch_here(self) -> None:
        if self.is_mounted:
            self.show_here()

    def on_mount(self) -> None:
        self.show_here()
        self.hide_later()

    def show_here(self) -> None:
        """Put the live position in the placeholders of the fields that default to it."""

    def here_text(self, j: int) -> str:
        """The placeholder of a field whose blank means "where joint ``j`` is"."""
        return f"here {self.here[j]:.2f}" if self.here else "here"

    def filled(self, field: NumberField, text: str, *, blank_too: bool = True) -> None:
        """Put ``text`` (from the position) in ``field``, unless the operator typed there
        since it was last filled (a blank one too, with ``blank_too``)."""
        current = field.text
        if current == self._filled.get(field.id or "") or (blank_too and not current):
            field.text = text
            self._filled[field.id or ""] = text

    def field(self, id: str) -> NumberField:
        return self.query_one(f"#{id}", NumberField)

    def joint(self) -> int:
        return self.query_one(JointField).index if self.machine.n_joints > 1 else 0

    def joint_fields(self, what: tuple[str, ...]) -> ComposeResult:
        """A joint chooser (unless there is one joint) and position fields for it: ``start``
        may be left blank (where the joint is), the others are required."""
        m = self.machine
        if m.n_joints > 1:
            yield JointField("joint", m.joints)
        j0 = m.joints[0]
        for name in what:
            optional = name == "start"
            yield NumberField(name, position_check(j0, m, name, optional=optional),
                              placeholder="here" if optional else "required", id=name)

    def show_start(self) -> None:
        """The ``start`` field's placeholder: the live position of the chosen joint."""
        self.field("start").input.placeholder = self.here_text(self.joint())

    @on(Select.Changed)
    def _joint_changed(self, event: Select.Changed) -> None:
        if isinstance(event.select.parent, JointField):
            joint = self.machine.joints[self.joint()]
            for f in self.query(NumberField):
                if f.id in ("start", "target", "end"):
                    set_position_limits(f, joint, self.machine, f.id)
            self.show_here()


class StepForm(MoveForm):
    KIND = "step"
    LABEL = "Step"
    HELP = ("One joint steps to a target; the others hold (option.c SingleStepInput; the "
            "rig's Step from a start to an end point).")

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "target"))
        yield NumberField("duration", seconds_check("duration", optional=True),
                          placeholder="auto", id="duration")

    def show_here(self) -> None:
        self.show_start()

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return form_plans.step(self.machine, current, self.joint(), self.field("target").value(),
                               self.field("start").value(), self.field("duration").value(),
                               dt=dt)


class MultiStepForm(MoveForm):
    KIND = "multi_step"
    LABEL = "Multi-step"
    HELP = ("Every joint steps to its own target at once (option.c MultiStepInput); a joint "
            "left blank stays where it is.")

    def fields(self) -> ComposeResult:
        for j, joint in enumerate(self.machine.joints):
            yield NumberField(joint.name, position_check(joint, self.machine, "target",
                                                         optional=True),
                              placeholder="here", id=f"target{j}")
        yield NumberField("duration", seconds_check("duration", optional=True),
                          placeholder="auto", id="duration")
        yield Button("Targets from the current position", id="from-current", compact=True)

    def show_here(self) -> None:
        for j in range(self.machine.n_joints):
            self.field(f"target{j}").input.placeholder = self.here_text(j)

    def fill(self, current: np.ndarray) -> None:
        for j in range(self.machine.n_joints):
            self.filled(self.field(f"target{j}"), f"{current[j]:.2f}", blank_too=False)

    @on(Button.Pressed, "#from-current")
    def _from_current(self, event: Button.Pressed) -> None:
        event.stop()
        if not self.here:
            self.notify("the controller has not reported where the joints are yet",
                        severity="warning")
            return
        for j in range(self.machine.n_joints):
            field = self.field(f"target{j}")
            field.text = ""  # what the button puts there is the position's, refreshed
            self.filled(field, f"{self.here[j]:.2f}")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        targets = [self.field(f"target{j}").value() for j in range(self.machine.n_joints)]
        return form_plans.multi_step(self.machine, current, targets,
                                     self.field("duration").value(), dt=dt)


class SequenceForm(MoveForm):
    KIND = "multi_step"
    LABEL = "Multi-step"
    HELP = ("Step to each position in turn and stay there for its dwell time "
            "(function.c MultiStep).")

    def fields(self) -> ComposeResult:
        joint = self.machine.joints[0]
        yield NumberField("steps", NumberCheck.of(count_rule("number of steps", MAX_SEQUENCE)),
                          f"{SEQUENCE_STEPS}", id="count")
        for i in range(MAX_SEQUENCE):
            with Horizontal(classes="sequence-row", id=f"row{i}"):
                yield NumberField(f"{i + 1}. position", position_check(joint, self.machine,
                                                                      f"step {i + 1} position"),
                                  id=f"pos{i}")
                yield NumberField("dwell", seconds_check(f"step {i + 1} dwell"), f"{DWELL_S:g}",
                                  id=f"dwell{i}")

    def on_mount(self) -> None:
        self._rows(SEQUENCE_STEPS)

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
        return form_plans.sequence(self.machine, current, steps, dt=dt)


class StartEndForm(MoveForm):
    """A one-joint move between a start (blank: where the joint is) and an end field."""

    def show_here(self) -> None:
        self.show_start()


class RampForm(StartEndForm):
    KIND = "ramp"
    LABEL = "Ramp"
    HELP = "From a start to an end position at constant speed, then hold (function.c RampInput)."

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "end"))
        yield NumberField("ramp time", seconds_check("ramp time"), f"{RAMP_TIME_S:g}",
                          id="ramp_time")
        yield NumberField("total", seconds_check("total duration", optional=True),
                          placeholder=f"auto: ramp + {SETTLE_TAIL_S:g} s", id="total")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return form_plans.ramp(self.machine, current, self.joint(), self.field("end").value(),
                               self.field("ramp_time").value(), self.field("start").value(),
                               self.field("total").value(), dt=dt)


class SineForm(StartEndForm):
    KIND = "sine"
    LABEL = "Sine"
    HELP = ("start + (end − start)/2 · (1 − cos 2πt/T): at the end at T/2, back at T "
            "(function.c Sinewave).")

    def fields(self) -> ComposeResult:
        yield from self.joint_fields(("start", "end"))
        yield NumberField("period T", seconds_check("period"), f"{SINE_PERIOD_S:g}", id="period")
        yield NumberField("duration", seconds_check("duration"), f"{SINE_DURATION_S:g}",
                          id="duration")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return form_plans.sine(self.machine, current, self.joint(), self.field("end").value(),
                               self.field("period").value(), self.field("duration").value(),
                               self.field("start").value(), dt=dt)


class PulseForm(MoveForm):
    KIND = "set_pulse"
    LABEL = "Set pulse"
    HELP = ("Open loop: a constant duty for a time, recorded (function.c SetPulse). Positive "
            "drives the ram up. The controller stops it at a limit.")

    def fields(self) -> ComposeResult:
        yield NumberField("duty", NumberCheck.of(duty_rule()), f"{PULSE_DUTY_PCT:g}", id="duty")
        yield NumberField("duration", seconds_check("duration", high=PULSE_MAX_S), f"{PULSE_S:g}",
                          id="duration")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return form_plans.pulse(self.machine, self.field("duty").value(),
                                self.field("duration").value(), dt=dt)


class InitialiseForm(MoveForm):
    KIND = "initialise"
    LABEL = "Initialise"
    HELP = ("Drive the ram down at 20 % until it rests on the bottom stop, then zero the "
            "encoder (section 3.5; function.c Initialise). Needed before any closed-loop move "
            "on the rig.")

    def plan(self, current: np.ndarray, dt: float) -> MovePlan:
        return MovePlan("initialise", "initialise")
