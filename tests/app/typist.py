"""An operator typing fast into the Moves forms of ``python -m app`` in tmux (terminal.py):
the real-terminal typing test's (test_typing_tmux.py) and the typing benchmark's
(benchmarks/typing.py).

A field is chosen with a mouse click (an SGR mouse report written to the pane, as the
terminal writes it), and typing starts once a probe typed slowly after it shows in the
field. A try clears the field with backspaces and
types a number, every key a ``tmux send-keys`` of its own ``gap_s`` after the one before,
as an operator's keys come; the field is read back from the screen. The test sends them and
reads the screen through one tmux control-mode client (``ControlTerminal``), not a tmux
process a command.
"""

from __future__ import annotations

import os
import re
import select
import subprocess
import time
from dataclasses import dataclass
from functools import partial
from types import TracebackType

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
        self.held = 0  # characters in the focused field, as far as the typist knows

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
        """Click in the field's box and type a probe at its end, until the field shows it
        (a click may miss when a banner that comes or goes moves the form). Each click's
        probe is its own (``0``, ``1``, …), so a probe that shows late, after the next click
        was sent, is never taken for the next one's. With one probe for every click, a first
        probe that showed only after its 5 s had passed passed for the second click's, and had
        the form moved meanwhile (a banner, an error line) and put that click in the next
        field, the keys typed next went there: a possible cause of the rare loss at load
        13-15 (Swivel's keys in duration), not reproduced."""
        deadline = time.monotonic() + WAIT_S
        attempt = 0
        while True:
            screen = self.term.wait(lambda s: find_field(s, label, unit) is not None,
                                    f"the {label} field")
            field = find_field(screen, label, unit)
            assert field is not None
            before = shown_text(screen, field)
            probe = str(attempt)
            self.click(field.row, field.column)
            self._send("-l", probe)
            try:
                screen = self.term.wait(partial(self.probed, field, before, probe),
                                        f"{probe} in {label}", timeout=CLICK_S)
            except TerminalError:
                if time.monotonic() > deadline:
                    raise
                attempt += 1
                continue
            self.held = len(shown_text(screen, field) or "")  # with every probe that came
            return field

    @staticmethod
    def probed(field: Field, before: str | None, probe: str, screen: str) -> bool:
        """This click's probe typed into the field: alone (it was empty) or after its value
        as the screen showed it before the click; an earlier click's probe that came in
        between makes neither. Not merely a new text ending in it: an empty field's
        placeholder is live ("here -0.09" became "here -0.10" as the rig settled), and was
        taken for the probe when no click had reached the field (a failure beside two
        burners). Nor a field that showed the probe already ("1" typed in a field of "1")."""
        text = shown_text(screen, field)
        return text != before and (text == probe
                                   or (before is not None and text == before + probe))

    def click(self, row: int, column: int) -> None:
        report = f"\x1b[<0;{column + 1};{row + 1}M\x1b[<0;{column + 1};{row + 1}m"
        self._send("-l", report)

    def type(self, text: str, clear: int = CLEAR, gap_s: float | None = None) -> None:
        """``clear`` backspaces then ``text``, a key every ``gap_s`` (the typist's)."""
        self.press(self.clearing(clear) + list(text), gap_s)
        self.held = len(text)

    def clearing(self, clear: int = CLEAR) -> list[str]:
        """``clear`` backspaces, or as many as the field holds characters if more (a value
        and the probes of three clicks that each took over 5 s to show)."""
        return ["BSpace"] * max(clear, self.held)

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
        self.term.keys(*args)


def number(k: int, low: float, high: float) -> str:
    """The ``k``-th number typed into a field of range ``low``…``high``: a different one
    each time, with one, two or no decimals, as an operator types them (whole numbers for
    whole bounds, a count)."""
    value = low + (high - low) * ((k * 0.618034) % 1.0)
    if isinstance(low, int) and isinstance(high, int):
        return str(round(value))
    decimals = 2 if high - low < 5 else k % 3 % 2
    return f"{value:.{decimals}f}"


class ControlTerminal(Terminal):
    """``term``'s session, its keys sent and its screen read through one tmux control-mode
    client (``tmux -C``) attached to it: a command costs the tmux server some 0.1 ms, where
    ``Terminal`` starts a tmux process a command, 5-7 ms of a core each, for every key sent
    and every screen read (thousands in the typing test), and reads the screen every 50 ms.
    The client neither sizes the window (``ignore-size``) nor takes the pane's output
    (``no-output``): the pane and what the app reads from it are as with no client."""

    poll_s = 0.005  # between screen reads while waiting: a read costs the tmux server ~0.1 ms

    def __init__(self, term: Terminal) -> None:
        super().__init__(term.socket, term.session, term.status_file)
        assert TMUX is not None, "tmux is not installed"
        self._client = subprocess.Popen(
            [TMUX, "-L", term.socket, "-f", os.devnull, "-u", "-C", "attach-session", "-t",
             term.session, "-f", "ignore-size,no-output"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self._read = b""
        self._reply("attach-session")  # the client's first, empty, reply

    def __enter__(self) -> ControlTerminal:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        assert self._client.stdin is not None
        self._client.stdin.close()  # the client detaches and exits
        try:
            self._client.wait(TMUX_S)
        except subprocess.TimeoutExpired:
            self._client.kill()
            self._client.wait()

    def command(self, *args: str) -> list[str]:
        """Run a tmux command; its output's lines."""
        assert self._client.stdin is not None
        quoted = ("'" + arg.replace("'", "'\"'\"'") + "'" for arg in args)  # taken literally
        self._client.stdin.write((" ".join(quoted) + "\n").encode())
        self._client.stdin.flush()
        return self._reply(" ".join(args[:1]))

    def _reply(self, what: str) -> list[str]:
        """The lines between ``%begin`` and its ``%end`` (``%error``: raised); the client's
        notifications outside them (``%session-changed`` …) are not ours."""
        deadline = time.monotonic() + TMUX_S
        while not (begin := self._line(deadline)).startswith("%begin "):
            pass
        number = begin.split()[2]
        lines: list[str] = []
        while True:
            line = self._line(deadline)
            end = line.split()
            if len(end) == 4 and end[0] in ("%end", "%error") and end[2] == number:
                if end[0] == "%error":
                    raise RuntimeError(f"tmux {what}: {' '.join(lines)}")
                return lines
            lines.append(line)

    def _line(self, deadline: float) -> str:
        assert self._client.stdout is not None
        while b"\n" not in self._read:
            ready, _, _ = select.select([self._client.stdout], [], [],
                                        max(0.0, deadline - time.monotonic()))
            chunk = os.read(self._client.stdout.fileno(), 1 << 16) if ready else b""
            if not chunk:
                raise TerminalError("tmux's control client " + (
                    "ended" if ready else f"gave no answer within {TMUX_S:g} s"))
            self._read += chunk
        line, self._read = self._read.split(b"\n", 1)
        return line.decode("utf-8", errors="replace")

    def screen(self) -> str:
        return "".join(f"{line}\n" for line in
                       self.command("capture-pane", "-p", "-t", self.session))

    def keys(self, *keys: str) -> None:
        self.command("send-keys", "-t", self.session, *keys)
