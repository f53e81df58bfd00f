"""The number fields of the move forms, as rules: what a typed value must be, and the error
that names the field and how to fix it.

The Moves tab's fields (``app.widgets.fields``) and ``servodesk move`` check what the
operator typed with these same rules, so a value one refuses the other refuses with the
same words.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from control.motion.path_files import MAX_MOVE_S
from hw.machine import Joint, Machine

# What a form's field holds until the operator types there (and ``servodesk move``'s defaults)
RAMP_TIME_S = 2.0
SINE_PERIOD_S = 4.0
SINE_DURATION_S = 8.0
DWELL_S = 2.0
SEQUENCE_STEPS = 3
MAX_SEQUENCE = 10
PULSE_DUTY_PCT = 20.0
PULSE_S = 1.0
PULSE_MAX_S = 60.0
VIA_SPEED = 0.5


class FieldError(ValueError):
    """A field holds no usable value; the message names the field and the fix."""


@dataclass(eq=False)  # compared and hashed as the object a field holds
class NumberRule:
    """A finite number, optionally within ``low…high`` (or above ``low`` when ``strict_low``).

    ``what`` names the quantity in messages (``"Up/Down target"``), ``unit``
    follows numbers, ``context`` is appended to range errors (``"machine rig"``).
    An empty field is valid when ``optional`` (the form then uses its default).
    Mutable: a form points a position field at another joint (``aim``).
    """

    what: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    strict_low: bool = False
    optional: bool = False
    nonzero: bool = False
    integer: bool = False
    context: str = ""

    def parse(self, text: str) -> float | None:
        """The value of ``text``, None for an empty optional field; FieldError otherwise."""
        text = text.strip()
        if not text:
            if self.optional:
                return None
            raise FieldError(f"{self.what}: enter a number")
        try:
            value = float(text)
        except ValueError:
            raise FieldError(f"{self.what}: {text!r} is not a number; type digits such as "
                             "12.5") from None
        if not math.isfinite(value):
            raise FieldError(f"{self.what}: {text} is not a usable number; enter a finite "
                             "value")
        if self.integer and value != int(value):
            raise FieldError(f"{self.what}: enter a whole number, not {text}")
        if self.nonzero and value == 0:
            raise FieldError(f"{self.what}: must not be 0")
        self._check_range(value)
        return value

    def _check_range(self, value: float) -> None:
        low, high, u = self.low, self.high, self.unit
        ctx = f" ({self.context})" if self.context else ""
        too_low = low is not None and (value <= low if self.strict_low else value < low)
        too_high = high is not None and value > high
        if not (too_low or too_high):
            return
        if low is not None and high is not None and self.strict_low:  # low itself is out too
            raise FieldError(f"{self.what} {value:g}{u} is out of range: it must be more than "
                             f"{low:g}{u} and at most {high:g}{u}{ctx}")
        if low is not None and high is not None:
            rng = f"{low:g}…{high:g}{u}"
            raise FieldError(f"{self.what} {value:g}{u} is outside {rng}{ctx}; enter a value in "
                             "that range")
        if too_low:
            bound = "above" if self.strict_low else "at least"
            raise FieldError(f"{self.what} must be {bound} {low:g}{u}{ctx}, not {value:g}{u}")
        raise FieldError(f"{self.what} must be at most {high:g}{u}{ctx}, not {value:g}{u}")

    def aim(self, joint: Joint, machine: Machine, what: str) -> None:
        """Make this a position rule of ``joint`` (``position_rule``), keeping ``optional``."""
        self.what = f"{joint.name} {what}"
        self.unit = joint.symbol
        self.low, self.high = joint.lower, joint.upper
        self.context = f"machine {machine.name}"


def position_rule(joint: Joint, machine: Machine, what: str, optional: bool = False
                  ) -> NumberRule:
    """A position of ``joint`` inside its limits."""
    return NumberRule(f"{joint.name} {what}", joint.symbol, joint.lower, joint.upper,
                      optional=optional, context=f"machine {machine.name}")


def seconds_rule(what: str, optional: bool = False, high: float = MAX_MOVE_S) -> NumberRule:
    """A time in seconds, above 0 and at most ``high`` (the longest move)."""
    return NumberRule(what, " s", 0.0, high, strict_low=True, optional=optional)


def fraction_rule(what: str) -> NumberRule:
    """A share of every joint's max speed: above 0, at most 1."""
    return NumberRule(what, "", 0.0, 1.0, strict_low=True)


def duty_rule() -> NumberRule:
    """An open-loop duty in %, not 0."""
    return NumberRule("duty", " %", -100, 100, nonzero=True)


def count_rule(what: str, most: int) -> NumberRule:
    """A whole number of things, 1…``most``."""
    return NumberRule(what, "", 1, most, integer=True)


def pose_rule(what: str, unit: str) -> NumberRule:
    """One coordinate of an end-effector pose (mm or °): any finite number."""
    return NumberRule(what, unit)
