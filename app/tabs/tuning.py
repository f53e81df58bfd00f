"""Tuning: the hold and track coefficient sets of eq. 5.1, per joint, edited live.

The controller copies a set from shared memory at its next tick, even during a
move (section 6.3), so an edit here changes the loop within a millisecond.
Presets are the machine file's extra sets (the P.I. gains of section 5.4.2,
the rig's observer controller of section 3.6.2) and any loaded from a file.

With care: every apply goes through the client's gain check, run off the UI's
thread (its first run imports scipy.signal: 1-3 s under load, during which the
UI, Esc's E-stop included, keeps taking keys), and a set it refuses is shown
with the reason in the tab, nothing applied; Load shows what
the file's sets would change in the live ones and applies them only when
confirmed (all or none); Save asks before replacing a file; ctrl+z puts back
the set in use before the last apply. A TUI that does not command changes nothing here
(``Desk.refusal``): no edit, apply or Save; its Load reads only files inside the data
directory (``Desk.typed_path``) and offers their sets as presets.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import ClassVar

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, RadioButton, RadioSet, Select, Static

from app.coefficient_files import (
    CoefficientFileError,
    coefficient_changes,
    coefficient_path,
    load_coefficients,
    save_coefficients,
)
from app.desk import Desk
from app.refusal_text import in_tui_words
from app.tabs.tab import TabPage
from app.widgets.dialogs import ConfirmScreen, EditValueScreen, ReviewScreen
from control.client import ControlClient, ControllerError
from control.rt.layout import MAX_TAPS, Mode
from hw.machine import COEFFICIENT, FILTER_DIVISOR, Coefficients

JOINT_COLUMNS = ("joint", "kp taps", "ki", "kd", "w taps", "kv feed-forward")
COMMON_COLUMNS = ("filter taps", "filter divisor", "integral limit", "duty limit %")


def parse_taps(text: str, allow_empty: bool = True) -> tuple[float, ...]:
    """``"0.0842, -0.0751"`` → taps, newest first; ValueError with the fix."""
    parts = [p for p in text.replace(";", ",").replace(" ", ",").split(",") if p]
    if not parts and not allow_empty:
        raise ValueError("enter at least one number")
    try:
        taps = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{text!r}: enter numbers separated by commas, newest tap first") \
            from None
    if not all(math.isfinite(t) for t in taps):
        raise ValueError("taps must be finite numbers")
    if any(abs(t) > COEFFICIENT for t in taps):
        raise ValueError(f"taps must lie within ±{COEFFICIENT:g}, as in a machine file")
    if len(taps) > MAX_TAPS:
        raise ValueError(f"{len(taps)} taps: the controller takes at most {MAX_TAPS}")
    return taps


def parse_number(text: str, low: float = -math.inf, high: float = math.inf,
                 strict_low: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError("enter a finite number")
    if (value <= low if strict_low else value < low) or value > high:
        bound = f"> {low:g}" if strict_low else f"≥ {low:g}"
        raise ValueError(f"{value:g} is out of range: enter a value {bound}"
                         + (f" and ≤ {high:g}" if math.isfinite(high) else ""))
    return value


def _kv(c: Coefficients, j: int) -> float:
    """Velocity feed-forward of joint ``j`` (% per unit/s); a set without it has none."""
    return c.kv[j] if c.kv else 0.0


def _taps_text(taps: tuple[float, ...]) -> str:
    return ", ".join(f"{t:g}" for t in taps) or "–"


@dataclass(frozen=True)
class Applied:
    """One apply, for undo: the set ``which`` held before (and what its gain check said of
    it), and the set the apply put in its place."""

    which: str
    before: Coefficients
    before_check: dict[str, object]
    applied: Coefficients
    what: str


class TuningTab(TabPage):
    """Hold and track sets in a table; Enter on a cell edits it and applies it live."""

    TITLE = "Tuning"
    LATER = ("#tuning-joints", "#tuning-common, #tuning-files")
    REFRESH_HZ = 2.0
    BINDINGS: ClassVar = [Binding("ctrl+z", "undo", "undo last apply", key_display="^Z")]

    @dataclass
    class Loaded(Message, bubble=False):
        """Coefficient sets read from ``path`` (from the file worker)."""

        path: Path
        sets: dict[str, Coefficients]

    @dataclass
    class Checked(Message, bubble=False):
        """The gain check of ``sets`` ended (from the check worker): ``refusal`` its error,
        None if every set passed."""

        sets: dict[str, Coefficients]
        what: str
        refusal: Exception | None

    @dataclass
    class OverwriteAsked(Message, bubble=False):
        """Saving would replace the file at ``path`` (from the file worker)."""

        path: Path

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.which = "track"
        self.presets: dict[str, Coefficients] = {}
        self.undo_stack: list[Applied] = []
        self.checking: str | None = None  # what the check worker checks now
        self.waiting: deque[tuple[dict[str, Coefficients], str]] = deque()  # applies behind it

    def compose(self) -> ComposeResult:
        self.presets = {name: c for name, c in self.machine.coefficients.items()}
        with Horizontal(id="tuning-controls"):
            with RadioSet(id="tuning-which"):
                yield RadioButton("hold set", value=False, id="which-hold")
                yield RadioButton("track set", value=True, id="which-track")
            yield Label("preset", classes="field-label")
            yield Select([(self._preset_label(n), n) for n in self.presets], id="tuning-preset",
                         allow_blank=False, value="track", compact=True)
            yield Button("Apply preset", id="tuning-apply-preset", variant="warning")
        yield Static(id="tuning-state")
        yield Static(id="tuning-outcome")
        yield DataTable(id="tuning-joints", cursor_type="cell", zebra_stripes=True)
        yield DataTable(id="tuning-common", cursor_type="cell")
        with Horizontal(id="tuning-files"):
            yield Label("file", classes="field-label")
            yield Input(placeholder="coefficients.toml", id="tuning-path", compact=True)
            yield Button("Load", id="tuning-load")
            yield Button("Save hold + track", id="tuning-save")

    def on_mount(self) -> None:
        joints = self.query_one("#tuning-joints", DataTable)
        joints.add_columns(*JOINT_COLUMNS)
        common = self.query_one("#tuning-common", DataTable)
        common.add_columns(*COMMON_COLUMNS)
        self.query_one("#tuning-path", Input).value = str(
            self.desk.data_dir.parent / f"{self.machine.name}-coefficients.toml")
        self._fill()

    def focus_main(self) -> None:
        self.query_one("#tuning-joints", DataTable).focus()

    def shown(self) -> None:
        self._fill()  # another tab (Identify) may have changed the sets
        super().shown()

    @property
    def current(self) -> Coefficients:
        client = self.connection
        if client is not None:
            return client.coefficients[self.which]
        return self.machine.coefficients[self.which]

    def _preset_label(self, name: str) -> str:
        note = self.presets[name].note
        return f"{name} — {note}" if note and note != name else name

    def _fill(self) -> None:
        c = self.current
        joints = self.query_one("#tuning-joints", DataTable)
        row, col = joints.cursor_coordinate
        joints.clear()
        for j, joint in enumerate(self.machine.joints):
            joints.add_row(joint.name, _taps_text(c.kp[j]), f"{c.ki[j]:g}", f"{c.kd[j]:g}",
                           _taps_text(c.w[j]), f"{_kv(c, j):g}", key=str(j))
        joints.move_cursor(row=row, column=max(1, col))
        common = self.query_one("#tuning-common", DataTable)
        common.clear()
        common.add_row(_taps_text(c.filter), f"{c.filter_divisor:g}", f"{c.integral_limit:g}",
                       f"{c.duty_limit:g}")
        self.refresh_live()

    def refresh_live(self) -> None:
        status = self.status()
        in_use = ""
        if status is not None:
            active = "hold" if status.mode == Mode.HOLD else (
                "track" if status.mode == Mode.FOLLOW_TRACK else "")
            in_use = ("  · in use now" if active == self.which else
                      f"  · the controller uses the {active} set now" if active else
                      "  · open loop now: no set in use")
        c = self.current
        self.query_one("#tuning-state", Static).update(Text.assemble(
            (f"{self.which} set ", "bold"), f"({c.name}: {c.note})", (in_use, "green"),
            ("   Enter on a cell edits it; the change applies at the next tick; ^Z undoes the "
             "last apply", "dim")))

    def on_radio_set_changed(self, event: RadioSet.Changed) -> None:
        event.stop()
        self.which = "hold" if event.pressed.id == "which-hold" else "track"
        self._fill()
        self._preset_of_set()

    def _preset_of_set(self) -> None:
        """The preset list on the set chosen: its preset by name, else the machine's own (the
        list said "track" with the hold set chosen)."""
        name = self.current.name
        name = name if name in self.presets else self.which
        if name in self.presets:
            self.query_one("#tuning-preset", Select).value = name

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "tuning-apply-preset":
            name = self.query_one("#tuning-preset", Select).value
            if isinstance(name, str) and name in self.presets:
                self.apply({self.which: replace(self.presets[name])}, f"preset {name}")
        elif event.button.id == "tuning-load":
            self.action_load()
        elif event.button.id == "tuning-save":
            self.action_save()

    def _refused(self, what: str) -> bool:
        """Say so in the tab and log it if this TUI may not ``what`` (it does not command)."""
        refusal = self.desk.refusal(what)
        if refusal:
            self._outcome(Text(refusal, "bold red"))
            self.notify(refusal, severity="error", timeout=8)
        return bool(refusal)

    # -- applying, and undoing ----------------------------------------------------------------

    def apply(self, sets: dict[str, Coefficients], what: str) -> None:
        """Check ``sets`` (hold and/or track) off the UI's thread, then apply them: all of
        them, or, if the check refuses one, none, with the reason shown in the tab. Applies
        asked for while a check runs wait behind it, in order."""
        if self._refused(f"apply {what}"):
            return
        if self.client is None:
            self.notify(f"apply {what}: the controller is not running — "
                        + (self.client_problem or "wait for it to start"), severity="error")
            return
        self.waiting.append((sets, what))
        if self.checking is None:
            self._check_next()
        else:
            self._outcome(Text(f"{what}: waits for the check of {self.checking}", "yellow"))

    def _check_next(self) -> None:
        sets, what = self.waiting.popleft()
        client = self.client
        if client is None:
            self._not_applied(what, ControllerError(
                self.client_problem or "the controller is not running"))
            return
        self.checking = what
        self._outcome(Text(f"{what}: checking the gains…", "yellow"))
        self.check(client, sets, what)

    @work(thread=True, group="tuning-check")
    def check(self, client: ControlClient, sets: dict[str, Coefficients], what: str) -> None:
        """The client's gain check of every set before any is applied (``set_coefficients``
        checks each again as it applies it, by then in milliseconds)."""
        from control.identify import gains  # scipy: loaded on first use

        try:
            for c in sets.values():
                gains.check(c, self.machine, client.models, client.dt)
        except ValueError as exc:
            self.post_message(self.Checked(sets, what, exc))
            return
        self.post_message(self.Checked(sets, what, None))

    def on_tuning_tab_checked(self, message: Checked) -> None:
        """Apply what was checked, then check the next apply waiting, if any."""
        self._apply_checked(message.sets, message.what, message.refusal)
        self.checking = None
        while self.waiting and self.checking is None:
            self._check_next()

    def _apply_checked(self, sets: dict[str, Coefficients], what: str,
                       refusal: Exception | None) -> None:
        """Apply the sets the check passed, one after the other, each through
        ``set_coefficients``; or say why not (``refusal``), nothing applied."""
        client = self.client
        if refusal is not None:
            self._not_applied(what, refusal)
            return
        if client is None:
            self._not_applied(what, ControllerError(
                self.client_problem or "the controller is not running"))
            return
        applied: list[Applied] = []
        try:
            for which, c in sets.items():
                before = Applied(which, client.coefficients[which],
                                 client.coefficient_checks[which], c, what)
                client.set_coefficients(which, c)
                applied.append(before)
        except (ControllerError, ValueError, OSError) as exc:
            self.undo_stack.extend(applied)  # only a dying controller stops after the first
            self._not_applied(what, exc)
            return
        self.undo_stack.extend(applied)
        names = " and ".join(sets) + (" sets" if len(sets) > 1 else " set")
        self._outcome(Text(f"{what} applied to the {names}; ^Z puts back the one before",
                           "green"))
        self.notify(f"{what} applied to the {names}")
        self._fill()

    def _not_applied(self, what: str, exc: Exception) -> None:
        reason = in_tui_words(exc)
        self.desk.log_refusal(f"apply {what}", reason)
        self._outcome(Text.assemble((f"{what}: ", "bold"), (reason, "bold red")))
        self.notify(f"apply {what}: {reason}", severity="error", timeout=10)
        self._fill()

    def action_undo(self) -> None:
        """Put back the set in use before the last apply made here."""
        client = self.client
        if not self.undo_stack:
            self.notify("undo: nothing applied from this tab to undo")
            return
        if client is None:
            self.notify("undo: the controller is not running", severity="error")
            return
        last = self.undo_stack.pop()
        if client.coefficients[last.which] != last.applied:
            self._outcome(Text(f"undo: the {last.which} set has changed since {last.what} "
                               f"(now {client.coefficients[last.which].name!r}); not undone",
                               "bold red"))
            self.notify(f"undo: the {last.which} set has changed since {last.what}; not undone",
                        severity="warning")
            return
        override = None
        if last.before_check.get("overridden"):
            override = (f"undo: the set in use before, applied with an override "
                        f"({last.before_check.get('override_reason')})")
        try:
            client.set_coefficients(last.which, last.before, override=override)
        except (ControllerError, ValueError, OSError) as exc:
            self.undo_stack.append(last)
            self._outcome(Text.assemble(("undo: ", "bold"), (in_tui_words(exc), "bold red")))
            self.notify(f"undo: {in_tui_words(exc)}", severity="error", timeout=10)
            return
        self._outcome(Text(f"undone: {last.what}; the {last.which} set is "
                           f"{last.before.name!r} again", "yellow"))
        self.notify(f"undone: {last.what}")
        self._fill()

    def _outcome(self, text: Text) -> None:
        self.query_one("#tuning-outcome", Static).update(text)

    # -- editing a cell ---------------------------------------------------------------------

    def on_data_table_cell_selected(self, event: DataTable.CellSelected) -> None:
        event.stop()
        self.edit(event.data_table.id or "", event.coordinate.row, event.coordinate.column)

    def edit(self, table: str, row: int, column: int) -> None:
        if self._refused(f"edit the {self.which} set"):
            return
        c = self.current
        if table == "tuning-joints":
            if column == 0:
                return
            joint = self.machine.joints[row]
            name = JOINT_COLUMNS[column]
            value = [None, _taps_text(c.kp[row]), f"{c.ki[row]:g}", f"{c.kd[row]:g}",
                     _taps_text(c.w[row]), f"{_kv(c, row):g}"][column]
            title = f"{self.which} set · {joint.name} · {name}"
        else:
            name = COMMON_COLUMNS[column]
            value = [_taps_text(c.filter), f"{c.filter_divisor:g}", f"{c.integral_limit:g}",
                     f"{c.duty_limit:g}"][column]
            title = f"{self.which} set · all joints · {name}"
        parse = self._parser(table, column)
        hint = ("taps newest first, separated by commas (empty for none)" if "taps" in name
                else "a number")

        def done(text: str | None) -> None:
            if text is not None:
                self.apply({self.which: self._changed(c, table, row, column, text)},
                           f"{title} = {text}")

        self.app.push_screen(EditValueScreen(title, "" if value == "–" else str(value), parse,
                                             hint), done)

    def _parser(self, table: str, column: int):
        """The check of a cell: the machine file's range for its key (docs/machines.md), so
        every set the tab builds can be saved and loaded back."""
        gain = partial(parse_number, low=-COEFFICIENT, high=COEFFICIENT)
        if table == "tuning-joints":
            return {1: lambda s: parse_taps(s, allow_empty=False), 2: gain,
                    3: gain, 4: parse_taps, 5: gain}[column]
        return {0: lambda s: parse_taps(s, allow_empty=False),
                1: lambda s: parse_number(s, *FILTER_DIVISOR),
                2: lambda s: parse_number(s, 0.0, COEFFICIENT),
                3: lambda s: parse_number(s, 0.0, 100.0, strict_low=True)}[column]

    def _changed(self, c: Coefficients, table: str, row: int, column: int,
                 text: str) -> Coefficients:
        value = self._parser(table, column)(text)
        if table == "tuning-joints":
            field = ("kp", "ki", "kd", "w", "kv")[column - 1]
            values = list(getattr(c, field) or [0.0] * self.machine.n_joints)  # kv: () is none
            values[row] = value
            return replace(c, **{field: tuple(values)})
        field = ("filter", "filter_divisor", "integral_limit", "duty_limit")[column]
        return replace(c, **{field: value})

    # -- files --------------------------------------------------------------------------------

    def action_load(self) -> None:
        """Read the typed file; a TUI that does not command only inside the data directory."""
        try:
            path = self.desk.typed_path(self.query_one("#tuning-path", Input).value, "load")
        except ValueError as exc:
            self._outcome(Text(str(exc), "bold red"))
            self.notify(str(exc), severity="error", timeout=10)
            return
        self.load(path)

    @work(thread=True, group="tuning-file")
    def load(self, path: Path) -> None:
        try:
            sets = load_coefficients(path, self.machine)
        except CoefficientFileError as exc:
            self.notify(f"{exc}. Fix the file or choose another.", severity="error", timeout=10)
            return
        self.post_message(self.Loaded(path, sets))

    def on_tuning_tab_loaded(self, message: Loaded) -> None:
        """Offer the file's sets as presets, show what applying it would change, and apply
        only if the operator confirms."""
        path, sets = message.path, message.sets
        for name, c in sets.items():
            self.presets[f"{path.stem}:{name}"] = c
        select = self.query_one("#tuning-preset", Select)
        select.set_options([(self._preset_label(n), n) for n in self.presets])
        select.value = f"{path.stem}:{next(iter(sets))}"
        assigned = {which: sets[name] for which, name in self._assign(sets).items()}
        review, changes = self._review(path, sets, assigned)
        if changes and not self.desk.commanding:  # read, but never offered to apply
            refusal = self.desk.refusal(f"apply {path.name}")
            said = (f"{path.name}: {changes} change(s) to the live sets, offered as presets "
                    f"only; {refusal}")
            self._outcome(Text(said, "bold yellow"))
            self.notify(said, severity="warning", timeout=8)
            return
        if not changes:
            self._outcome(Text(f"{path.name}: the same as the sets in use; nothing to apply",
                               "green"))
            return
        targets = " and ".join(assigned) + (" sets" if len(assigned) > 1 else " set")

        def answer(yes: bool | None) -> None:
            if yes:
                self.apply(assigned, path.name)
            else:
                self._outcome(Text(f"{path.name} not applied; its sets are offered as presets",
                                   "yellow"))

        self.app.push_screen(ReviewScreen(
            f"Apply {path.name} to the {targets}?",
            f"{changes} change(s) to the live set; the controller takes them at its next tick, "
            "even during a move. ^Z undoes it afterwards.", review, "Apply"), answer)

    def _assign(self, sets: dict[str, Coefficients]) -> dict[str, str]:
        """Which of a file's sets replaces each live set: one named hold or track replaces
        that set; a file with neither puts its first set in the set shown (the others are
        presets only)."""
        named = {which: which for which in ("hold", "track") if which in sets}
        return named or {self.which: next(iter(sets))}

    def _review(self, path: Path, sets: dict[str, Coefficients],
                assigned: dict[str, Coefficients]) -> tuple[Text, int]:
        """The differences between each assigned set and the live one, and how many."""
        client = self.connection
        text, count = Text(), 0
        for which, c in assigned.items():
            live = client.coefficients[which] if client is not None else \
                self.machine.coefficients[which]
            rows = coefficient_changes(live, c, self.machine)
            count += len(rows)
            text.append(f"{which} set ← {c.name!r} from {path.name}", "bold")
            text.append(f"  (in use: {live.name!r})\n", "dim")
            if not rows:
                text.append("  the same as the set in use\n", "dim")
            for joint, key, old, new in rows:
                text.append(f"  {joint:<11} {key:<15} {old} → ", "")
                text.append(f"{new}\n", "bold")
        chosen = {c.name for c in assigned.values()}
        others = [name for name in sets if name not in chosen]
        if others:
            text.append(f"also in the file, offered as presets only: {', '.join(others)}",
                        "dim")
        return text, count

    def action_save(self) -> None:
        """Save the sets in use to the typed file, if this TUI commands (it is a gain file)."""
        if not self._refused("save"):
            self.save(self.query_one("#tuning-path", Input).value)

    @work(thread=True, group="tuning-file")
    def save(self, path: str, overwrite: bool = False) -> None:
        target = coefficient_path(path)
        if not overwrite and target.exists():
            self.post_message(self.OverwriteAsked(target))
            return
        client = self.connection
        sets = dict(client.coefficients) if client is not None else {
            "hold": self.machine.hold, "track": self.machine.track}
        try:
            written = save_coefficients(path, sets, self.machine)
        except CoefficientFileError as exc:
            self.notify(f"{exc}. Choose another path.", severity="error", timeout=10)
            return
        self.notify(f"saved the hold and track sets to {written}")

    def on_tuning_tab_overwrite_asked(self, message: OverwriteAsked) -> None:
        def answer(yes: bool | None) -> None:
            if not yes:
                self.notify(f"not saved: {message.path} left as it was")
            elif not self._refused("save"):  # command may have been released meanwhile
                self.save(str(message.path), overwrite=True)

        self.app.push_screen(ConfirmScreen(
            f"Overwrite {message.path.name}?",
            f"{message.path} exists. Saving replaces it with the hold and track sets in use "
            "now.", "Overwrite"), answer)
