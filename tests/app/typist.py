"""An operator typing fast into the Moves forms of ``python -m app`` in tmux (terminal.py):
the real-terminal typing test's (test_typing_tmux.py) and the typing benchmark's
(benchmarks/typing.py).

A field is chosen with a mouse click (an SGR mouse report written to the pane, as the
terminal writes it), and typing starts once a probe key typed slowly after it shows in the
field. A try clears the field with backspaces and
types a number, every key a ``tmux send-keys`` of its own ``gap_s`` after the one before,
as an operator's keys come; the field is read back from the screen.
"""

from __future__ import annotations

import re
import subprocess
import time
from dataclasses import dataclass
from functools import partial

from tests.app.terminal import TMUX, TMUX_S, WAIT_S, Terminal, TerminalError

# The Unimate 2000B's Moves forms (menu order): the menu's label, how the help text under
# it starts, and the numeric fields: label and unit as
# the form shows them (the joint chooser left at its first joint, In/Out), and a range the
# numbers typed there come from, inside the field's limits (an error line under a field
# would push the last ones out of view).
IN_OUT, ANGLE, SECONDS = (1000.0, 2000.0), (-25.0, 25.0), (1.0, 60.0)
FORMS: tuple[tuple[str, str, tuple[tuple[str, str, tuple[float, float]], ...]], ...] = (
    ("Step", "One joint steps",
     (("start", "mm", IN_OUT), ("target", "mm", IN_OUT), ("duration", "s", SECONDS))),
    ("Multi-step", "Every joint steps",
     (("In/Out", "mm", IN_OUT), ("Rotate", "°", ANGLE), ("Up/Down", "°", ANGLE),
      ("Bend", "°", ANGLE), ("Yaw", "°", ANGLE), ("Swivel", "°", ANGLE),
      ("duration", "s", SECONDS))),
    ("Ramp", "From a start to an end",
     (("start", "mm", IN_OUT), ("end", "mm", IN_OUT), ("ramp time", "s", SECONDS),
      ("total", "s", (61.0, 120.0)))),
    ("Sine", "start + (end",
     (("start", "mm", IN_OUT), ("end", "mm", IN_OUT), ("period T", "s", SECONDS),
      ("duration", "s", SECONDS))),
    ("End point", "End-effector position",
     (("x", "mm", (1000.0, 1600.0)), ("y", "mm", (-300.0, 300.0)), ("z", "mm", (500.0, 900.0)),
      ("γ", "°", ANGLE), ("β", "°", ANGLE), ("α", "°", ANGLE), ("ramp time", "s", SECONDS))),
    ("Via points", "A smooth path from here", (("speed fraction", "", (0.05, 1.0)),)),
)
# The rig's Moves forms, as FORMS (its one joint, the Ram; whole numbers for a count).
RAM = (100.0, 1100.0)
RIG_FORMS: tuple[tuple[str, str, tuple[tuple[str, str, tuple[float, float]], ...]], ...] = (
    ("Step", "One joint steps",
     (("start", "mm", RAM), ("target", "mm", RAM), ("duration", "s", SECONDS))),
    ("Multi-step", "Step to each position",
     (("steps", "", (1, 10)), ("1. position", "mm", RAM), ("dwell", "s", SECONDS))),
    ("Ramp", "From a start to an end",
     (("start", "mm", RAM), ("end", "mm", RAM), ("ramp time", "s", SECONDS),
      ("total", "s", (61.0, 120.0)))),
    ("Sine", "start + (end",
     (("start", "mm", RAM), ("end", "mm", RAM), ("period T", "s", SECONDS),
      ("duration", "s", SECONDS))),
    ("Set pulse", "Open loop",
     (("duty", "%", (5.0, 100.0)), ("duration", "s", SECONDS))),
)
# The numeric fields of the Unimate's other tabs: the tab's key, and its fields as above.
TAB_FIELDS: tuple[tuple[str, tuple[tuple[str, str, tuple[float, float]], ...]], ...] = (
    ("F8", (("amplitude", "%", (1.0, 100.0)), ("duration", "s", SECONDS))),
    ("F9", (("speed fraction", "", (0.05, 1.0)),)),
)
CLICK_INTO = 8  # a value typed here has at most this many characters (with the probe)
MENU_WIDTH = 24  # the Moves menu's column: a form's name left of it is the menu's
CLICK_S = 5.0  # a click's probe on the screen: well under a second unloaded; else click again
PROBE = "0"  # typed after a click, slowly: the field that shows it has the focus
CLEAR = 10  # backspaces before each number: more than any number typed here has characters


@dataclass(frozen=True)
class Field:
    """Where to click a field's box on the screen (0-based cells): just past a value of up to
    ``CLICK_INTO`` characters (the cursor then at its end), inside a longer placeholder (an
    empty field's cursor is at its end wherever clicked), or in an empty box."""

    label: str
    unit: str
    row: int
    column: int


def field_pattern(label: str, unit: str) -> re.Pattern[str]:
    """A field's row: its label, two spaces or more, its text (a value, a placeholder or
    nothing) and its unit (none for a fraction: the end of the box)."""
    end = rf" {{2,}}{re.escape(unit)}" if unit else r"(?: {2,}|$)"
    return re.compile(rf"(?<!\S){re.escape(label)}(?P<gap> {{2,}})(?P<text>\S(?:.*?\S)?)?{end}",
                      re.MULTILINE)


def find_field(screen: str, label: str, unit: str) -> Field | None:
    pattern = field_pattern(label, unit)
    for row, line in enumerate(screen.splitlines()):
        match = pattern.search(line)
        if match:
            text = match.group("text") or ""
            if not text:  # an empty box ends where its unit begins
                return Field(label, unit, row, match.end() - len(unit) - 2)
            return Field(label, unit, row, match.start("text") + min(len(text), CLICK_INTO))
    return None


def shown_text(screen: str, field: Field) -> str | None:
    """The text the field shows (a value, its placeholder when empty, or ""), wherever the
    form has scrolled it to; None when it is out of view."""
    match = field_pattern(field.label, field.unit).search(screen)
    return (match.group("text") or "") if match else None


class Typist:
    """Types into the fields of the app in ``term``, on the Moves tab."""

    def __init__(self, term: Terminal, gap_s: float) -> None:
        self.term = term
        self.gap_s = gap_s

    def open_moves(self) -> None:
        self.term.keys("F2")
        self.term.wait(lambda s: " Via points " in s, "the Moves tab's menu")

    def open_tab(self, key: str, label: str, unit: str) -> None:
        """Press the tab's key and wait for one of its fields."""
        self.term.keys(key)
        self.term.wait(lambda s: find_field(s, label, unit) is not None, f"{label} on {key}")

    def open_form(self, label: str, help_starts: str) -> None:
        """Click the form's entry in the Moves menu (the left column) and wait for it. A
        click on an entry focuses its form's first field too: not for the form shown."""
        screen = self.term.screen()
        if help_starts in screen:
            return
        for row, line in enumerate(screen.splitlines()):
            column = line.find(f" {label} ")
            if 0 <= column < MENU_WIDTH:
                self.click(row, column + 1)
                break
        else:
            raise TerminalError(f"no {label} in the Moves menu; the terminal shows:\n{screen}")
        self.term.wait(lambda s: help_starts in s, f"the {label} form")

    def focus(self, label: str, unit: str) -> Field:
        """Click in the field's box and type a ``PROBE`` at its end, until the field shows it
        (a click may miss when a banner that comes or goes moves the form)."""
        deadline = time.monotonic() + WAIT_S
        while True:
            screen = self.term.wait(lambda s: find_field(s, label, unit) is not None,
                                    f"the {label} field")
            field = find_field(screen, label, unit)
            assert field is not None
            before = shown_text(screen, field)
            self.click(field.row, field.column)
            self._send(PROBE)
            try:
                self.term.wait(partial(self.probed, field, before), f"{PROBE} in {label}",
                               timeout=CLICK_S)
            except TerminalError:
                if time.monotonic() > deadline:
                    raise
                continue
            return field

    @staticmethod
    def probed(field: Field, before: str | None, screen: str) -> bool:
        """The probe typed into the field: alone (it was empty) or after its value. Not merely
        a new text ending in it: an empty field's placeholder is live ("here -0.09" became
        "here -0.10" as the rig settled), and was taken for the probe when no click had
        reached the field (a failure beside two burners)."""
        text = shown_text(screen, field)
        return text == PROBE or (before is not None and text == before + PROBE)

    def click(self, row: int, column: int) -> None:
        report = f"\x1b[<0;{column + 1};{row + 1}M\x1b[<0;{column + 1};{row + 1}m"
        self._send("-l", report)

    def type(self, text: str, clear: int = CLEAR, gap_s: float | None = None) -> None:
        """``clear`` backspaces then ``text``, a key every ``gap_s`` (the typist's)."""
        self.press(["BSpace"] * clear + list(text), gap_s)

    def press(self, keys: list[str], gap_s: float | None = None) -> None:
        """tmux's key names, a key every ``gap_s`` (the typist's)."""
        gap_s = self.gap_s if gap_s is None else gap_s
        start = time.monotonic()
        for k, key in enumerate(keys):
            delay = start + k * gap_s - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self._send(key)

    def _send(self, *args: str) -> None:
        assert TMUX is not None
        subprocess.run([TMUX, "-L", self.term.socket, "send-keys", "-t", self.term.session,
                        *args], check=True, capture_output=True, timeout=TMUX_S)


def number(k: int, low: float, high: float) -> str:
    """The ``k``-th number typed into a field of range ``low``…``high``: a different one
    each time, with one, two or no decimals, as an operator types them (whole numbers for
    whole bounds, a count)."""
    value = low + (high - low) * ((k * 0.618034) % 1.0)
    if isinstance(low, int) and isinstance(high, int):
        return str(round(value))
    decimals = 2 if high - low < 5 else k % 3 % 2
    return f"{value:.{decimals}f}"
