"""Form fields validated as they are typed: a number with its unit, limits and an error
line that says how to fix it; a joint chooser. Used by the Moves and Identify tabs.

Their rules are in ``fields.tcss`` beside this module, loaded by the app rather than kept
in the classes: tabs lay out rows of their own with the same classes (``.field``,
``.field-label``, ``.field-select``) and adjust them in their own stylesheets."""

from __future__ import annotations

from collections.abc import Sequence

from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.validation import ValidationResult, Validator
from textual.widgets import Input, Label, Select, Static

from app.widgets.typed import FieldInput
from control.motion.fields import FieldError, NumberRule, position_rule, seconds_rule
from control.motion.path_files import MAX_MOVE_S
from hw.machine import Joint, Machine

__all__ = ["FieldError", "JointField", "NumberCheck", "NumberField", "position_check",
           "seconds_check", "set_position_limits"]


class NumberCheck(NumberRule, Validator):
    """A ``NumberRule`` (``control.motion.fields``) checked as the field is typed."""

    def __init__(self, what: str, unit: str = "", low: float | None = None,
                 high: float | None = None, *, strict_low: bool = False, optional: bool = False,
                 nonzero: bool = False, integer: bool = False, context: str = "") -> None:
        NumberRule.__init__(self, what, unit, low, high, strict_low, optional, nonzero, integer,
                            context)
        Validator.__init__(self)

    @classmethod
    def of(cls, rule: NumberRule) -> NumberCheck:
        return cls(rule.what, rule.unit, rule.low, rule.high, strict_low=rule.strict_low,
                   optional=rule.optional, nonzero=rule.nonzero, integer=rule.integer,
                   context=rule.context)

    def validate(self, value: str) -> ValidationResult:
        try:
            self.parse(value)
        except FieldError as exc:
            return self.failure(str(exc))
        return self.success()


class NumberField(Vertical):
    """``label [ value ] unit`` on one row, and under it what is wrong and how to fix it."""

    DEFAULT_CLASSES = "field"

    def __init__(self, label: str, check: NumberCheck, value: str = "", *,
                 placeholder: str = "", id: str | None = None) -> None:
        super().__init__(id=id)
        self.label = label
        self.check = check
        self._initial = value
        self._placeholder = placeholder
        self.touched = False  # errors show once the operator typed here or pressed Run

    def compose(self) -> ComposeResult:
        with Horizontal(classes="field-row"):
            yield Label(self.label, classes="field-label")
            yield FieldInput(self._initial, placeholder=self._placeholder, validators=[self.check],
                        validate_on=["changed", "submitted"], compact=True,
                        classes="field-input")
            yield Static(self.check.unit, classes="field-unit")
        yield Static("", classes="field-error")

    @property
    def input(self) -> Input:
        return self.query_one(Input)

    @property
    def text(self) -> str:
        return self.input.value

    @text.setter
    def text(self, value: str) -> None:
        self.input.value = value

    def value(self) -> float | None:
        """The number typed, None if empty and optional; FieldError otherwise."""
        return self.check.parse(self.input.value)

    def check_now(self) -> bool:
        """Validate and show the error even if nothing was typed yet (Run was pressed)."""
        self.touched = True
        self.revalidate()
        return not self.has_class("-invalid")

    def revalidate(self) -> None:
        """Check again after the limits changed (a different joint was chosen)."""
        if not self.touched:
            return
        try:
            self.check.parse(self.input.value)
        except FieldError as exc:
            self.show_error(str(exc))
        else:
            self.show_error("")

    def show_error(self, message: str) -> None:
        error = self.query_one(".field-error", Static)
        error.update(message)
        error.display = bool(message)
        self.set_class(bool(message), "-invalid")

    def on_input_changed(self, event: Input.Changed) -> None:
        if event.value != self._initial:
            self.touched = True
        self.revalidate()  # by the check as it is now: a joint chosen since the value was set


def position_check(joint: Joint, machine: Machine, what: str, optional: bool = False
                   ) -> NumberCheck:
    """A position of ``joint`` inside its limits."""
    return NumberCheck.of(position_rule(joint, machine, what, optional))


def seconds_check(what: str, optional: bool = False, high: float = MAX_MOVE_S) -> NumberCheck:
    return NumberCheck.of(seconds_rule(what, optional, high))


def set_position_limits(field: NumberField, joint: Joint, machine: Machine, what: str) -> None:
    """Point ``field`` at another joint: new limits, unit and message, checked again."""
    field.check.aim(joint, machine, what)
    field.query_one(".field-unit", Static).update(joint.symbol)
    field.revalidate()


class JointField(Horizontal):
    """``label [joint ▾]``: which joint a single-joint move drives."""

    DEFAULT_CLASSES = "field"

    def __init__(self, label: str, joints: Sequence[Joint], *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.label = label
        self.joints = tuple(joints)

    def compose(self) -> ComposeResult:
        yield Label(self.label, classes="field-label")
        yield Select([(j.name, i) for i, j in enumerate(self.joints)], value=0,
                     allow_blank=False, compact=True, classes="field-select")

    @property
    def index(self) -> int:
        value = self.query_one(Select).value
        return int(value) if isinstance(value, int) else 0
