"""Tuning: the hold and track coefficient sets of eq. 5.1, per joint, edited live.

The controller copies a set from shared memory at its next tick, even during a
move (section 6.3), so an edit here changes the loop within a millisecond.
Presets are the machine file's extra sets (the P.I. gains of section 5.4.2,
the rig's observer controller of section 3.6.2) and any loaded from a file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.message import Message
from textual.widgets import Button, DataTable, Input, Label, RadioButton, RadioSet, Select, Static

from app.coefficient_files import CoefficientFileError, load_coefficients, save_coefficients
from app.desk import Desk
from app.tabs.tab import TabPage
from app.widgets.dialogs import EditValueScreen
from control.layout import MAX_TAPS, Mode
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


class TuningTab(TabPage):
    """Hold and track sets in a table; Enter on a cell edits it and applies it live."""

    TITLE = "Tuning"
    REFRESH_HZ = 2.0

    @dataclass
    class Loaded(Message, bubble=False):
        """Coefficient sets read from ``path`` (from the file worker)."""

        path: Path
        sets: dict[str, Coefficients]

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.which = "track"
        self.presets: dict[str, Coefficients] = {}

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
            ("   Enter on a cell edits it; the change applies at the next tick", "dim")))

    def on_radio_set_changed(self, event: RadioSet.Changed) -> None:
        event.stop()
        self.which = "hold" if event.pressed.id == "which-hold" else "track"
        self._fill()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "tuning-apply-preset":
            name = self.query_one("#tuning-preset", Select).value
            if isinstance(name, str) and name in self.presets:
                self.apply(replace(self.presets[name]), f"preset {name}")
        elif event.button.id == "tuning-load":
            self.load(self.query_one("#tuning-path", Input).value)
        elif event.button.id == "tuning-save":
            self.save(self.query_one("#tuning-path", Input).value)

    def apply(self, coefficients: Coefficients, what: str) -> None:
        if self.command(f"apply {what}",
                        lambda client: client.set_coefficients(self.which, coefficients)):
            self.notify(f"{what} applied to the {self.which} set")
        self._fill()

    # -- editing a cell ---------------------------------------------------------------------

    def on_data_table_cell_selected(self, event: DataTable.CellSelected) -> None:
        event.stop()
        self.edit(event.data_table.id or "", event.coordinate.row, event.coordinate.column)

    def edit(self, table: str, row: int, column: int) -> None:
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
                self.apply(self._changed(c, table, row, column, text), f"{title} = {text}")

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

    @work(thread=True, group="tuning-file")
    def load(self, path: str) -> None:
        try:
            sets = load_coefficients(path, self.machine)
        except CoefficientFileError as exc:
            self.notify(f"{exc}. Fix the file or choose another.", severity="error", timeout=10)
            return
        self.post_message(self.Loaded(Path(path), sets))

    def on_tuning_tab_loaded(self, message: Loaded) -> None:
        path, sets = message.path, message.sets
        for name, c in sets.items():
            self.presets[f"{path.stem}:{name}"] = c
        select = self.query_one("#tuning-preset", Select)
        select.set_options([(self._preset_label(n), n) for n in self.presets])
        first = f"{path.stem}:{next(iter(sets))}"
        select.value = first
        self.notify(f"loaded {', '.join(sets)} from {path}; choose a preset and press Apply")

    @work(thread=True, group="tuning-file")
    def save(self, path: str) -> None:
        client = self.connection
        sets = dict(client.coefficients) if client is not None else {
            "hold": self.machine.hold, "track": self.machine.track}
        try:
            written = save_coefficients(path, sets, self.machine)
        except CoefficientFileError as exc:
            self.notify(f"{exc}. Choose another path.", severity="error", timeout=10)
            return
        self.notify(f"saved the hold and track sets to {written}")
