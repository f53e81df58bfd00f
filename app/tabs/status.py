"""Status: the thesis's ``visual`` printer, better (section 5.1: position and PWM of each
joint every 300 interrupts). Here every joint's position, desired, error, duty, valve,
raw encoder word, glitch count and a limit bar; the end-effector pose from the forward
kinematics; the loop's sample number, mode, lateness, the hydraulic supply pressure and
the link counters.

Under ``FULL_WIDTH`` columns (an 80-column terminal) the joints' table leaves out the raw
word and the glitch count and shortens its numbers, so names, values and limit bars stay
whole; the tab scrolls when the screen is short."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from rich.text import Span, Text
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll

from app.tabs.tab import TabPage
from app.widgets.aligned_rows import GAP, AlignedRows, Cell
from app.widgets.header import MODE_NAMES, StatusHeader
from app.widgets.limit_bar import LimitBar
from app.widgets.live_text import LiveLines, LiveText
from control.rt.layout import Flag, Status
from hw.machine import Machine

POSE_LABELS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("γ", "°"), ("β", "°"), ("α", "°"))
FULL_WIDTH = 100  # columns the joints' table needs for every column


class StatusTab(TabPage):
    """Everything the controller publishes, ten times a second: drawn on the header's tick
    (no timer of its own), so that the header and the tab change in one screen update, not
    two (each update draws the screen's containers again, whatever changed)."""

    TITLE = "Status"
    LATER = ("#status-lower",)

    def compose(self) -> ComposeResult:
        with VerticalScroll(id="status-scroll"):  # a few lines change a tick: drawn alone
            yield LiveLines(id="status-joints")
            with Horizontal(id="status-lower"):
                yield LiveLines(id="status-pose")
                yield LiveLines(id="status-loop")
                yield LiveLines(id="status-link")

    def on_mount(self) -> None:
        self.query_one("#status-joints").styles.height = self.machine.n_joints + 2
        self._blocks = tuple(self.query_one(f"#status-{name}", LiveText)
                             for name in ("joints", "pose", "loop", "link"))
        # each block as last made, with what it was made from: a joint at rest, the pose
        # and the link counters read the same tick after tick, and are not made again
        self._made: dict[str, tuple[object, list[Text]]] = {}
        # each table's rows as laid out: a tick lays out again only the cells that changed
        self._tables = {
            "joints": AlignedRows(("left",) + ("right",) * 7, edge=" ", header=True),
            "joints narrow": AlignedRows(("left",) + ("right",) * 5),
            "pose": AlignedRows(("left", "right"), gap=1),
            "loop": AlignedRows(("left", "right"), gap=1),
            "link": AlignedRows(("left", "right"), gap=1)}
        self._bars: dict[int, tuple[tuple[int, int, int, str], Text]] = {}  # each joint's
        self._header = self.screen.query_one(StatusHeader)
        self.watch(self._header, "status", self._header_ticked, init=False)

    def _header_ticked(self) -> None:
        if self.visible_now:  # the status the header shows: not read and decoded again
            self._show(self._header.status if self.client is not None else None)

    def refresh_live(self) -> None:
        self._show(self.status())

    def _show(self, status: Status | None) -> None:
        joints, pose, loop, link = self._blocks
        if status is None:
            joints.show(Text("waiting for the controller…", "yellow"))
            return
        width = joints.size.width or FULL_WIDTH
        full = width >= FULL_WIDTH
        joints.show_rows(self._made_from(
            "joints", (status.position, status.desired, status.duty, status.valve, status.raw,
                       status.glitches, width),
            lambda: self._joints(status, width) if full else self._joints_narrow(status, width)))
        pose.show_rows(self._made_from("pose", (status.position, full),
                                       lambda: self._pose(status, full)))
        loop.show_rows(self._loop(status))
        link.show_rows(self._made_from("link", tuple(status.link.items()),
                                       lambda: self._link(status)))

    def _made_from(self, block: str, inputs: object, make: Callable[[], list[Text]]
                   ) -> list[Text]:
        """``block`` made by ``make`` from ``inputs``, or as last made if they are the same."""
        made = self._made.get(block)
        if made is not None and made[0] == inputs:
            return made[1]
        rows = make()
        self._made[block] = (inputs, rows)
        return rows

    # Each block is its lines of text in aligned columns, not a rich Table: a table's layout
    # cost 9 ms a frame at ten frames a second, most of the idle tab's CPU; nor one Text, which
    # the widget would split into its lines again each tick. Its rows are laid out again only
    # where they changed (``AlignedRows``): idle, every joint's glitch count changes a tick.

    def _joints(self, status: Status, width: int = FULL_WIDTH + 60) -> list[Text]:
        rows: list[list[Cell]] = [["joint", "position", "desired", "error", "duty %",
                                   "valve %", "raw", "glitches"]]
        for j, joint in enumerate(self.machine.joints):
            q, d = status.position[j], status.desired[j]
            e = d - q if math.isfinite(d) else math.nan
            rows.append([
                joint.name, f"{q:10.3f} {joint.symbol}", _num(d, joint.symbol),
                _num(e, joint.symbol), _pct(status.duty[j], 7), _pct(status.valve[j], 7),
                f"{status.raw[j]:#06x}",
                Text(str(status.glitches[j]), "yellow" if status.glitches[j] else "dim")])
        return self._with_bars(self._tables["joints"], status, rows, width, least=8)

    def _joints_narrow(self, status: Status, width: int = 80) -> list[Text]:
        """The joints' table in 80 columns: no raw word or glitches, two decimals."""
        rows: list[list[Cell]] = [["joint", "position", "desired", "error", "duty %",
                                   "valve %"]]
        for j, joint in enumerate(self.machine.joints):
            q, d = status.position[j], status.desired[j]
            e = d - q if math.isfinite(d) else math.nan
            rows.append([
                joint.name, f"{q:.2f} {joint.symbol}", _num(d, joint.symbol, ".2f"),
                _num(e, "", "+.3f"), _pct(status.duty[j]), _pct(status.valve[j])])
        return self._with_bars(self._tables["joints narrow"], status, rows, width, least=10)

    def _with_bars(self, table: AlignedRows, status: Status, rows: list[list[Cell]],
                   width: int, least: int) -> list[Text]:
        """``rows`` (a header, then a row a joint) in columns, each joint's limit bar in what
        the line has left (at least ``least`` columns), under the title "joints"."""
        def bars(used: int) -> list[Cell]:
            bar = max(least, width - used - len(table.edge) - GAP)
            return [Text("limits", "bold"), *(self._bar(j, status, bar)
                                              for j in range(self.machine.n_joints))]

        return [_title("joints"), *table.lines(rows, after=bars)]

    def _bar(self, j: int, status: Status, width: int) -> Text:
        """Joint ``j``'s limit bar ``width`` wide: as last drawn while its marks stay."""
        joint = self.machine.joints[j]
        marks = LimitBar(status.position[j], joint.lower, joint.upper,
                         status.desired[j]).marks(width)
        drawn = self._bars.get(j)
        if drawn is None or drawn[0] != marks:
            drawn = self._bars[j] = (marks, LimitBar.drawn(marks))
        return drawn[1]

    def _pose(self, status: Status, full: bool = True) -> list[Text]:
        if self.model is None:
            return [_title("end effector"),
                    Text.assemble(("no kinematic model for this machine", "dim"))]
        pose = self.model.pose(np.asarray(status.position))
        title = "end effector (X-Y-Z fixed, eq. 4.04)" if full else "end effector"
        return _block(title, self._tables["pose"],
                      [[name, f"{value:9.2f} {unit}"]
                       for (name, unit), value in zip(POSE_LABELS, pose, strict=True)])

    def _loop(self, status: Status) -> list[Text]:
        progress = (f"{status.move_done}/{status.move_total} (move {status.move_id})"
                    if status.move_total else "–")
        flags = ", ".join(f.name.lower().replace("_", " ") for f in Flag
                          if f in status.flags and f.name) or "–"
        return _block("loop", self._tables["loop"], [
            ["sample", f"{status.tick}"],
            ["controller time", f"{status.time_s:.3f} s"],
            ["mode", MODE_NAMES.get(status.mode, str(status.mode))],
            ["move", progress],
            ["lateness", f"{status.late_last_us:.1f} µs, max {status.late_max_us:.0f}"],
            ["compute", f"{status.compute_last_us:.1f} µs, max {status.compute_max_us:.0f}"],
            ["loop CPU", _share(status.compute_total_s, status.tick * self.machine.sample_time_s)],
            ["overruns", f"{status.overruns}"],
            ["supply", _supply(status.supply_mpa, self.machine)],
            ["flags", flags],
            ["fault", status.fault or "–"],
        ])

    def _link(self, status: Status) -> list[Text]:
        rows: list[list[Cell]] = []
        for name, value in status.link.items():
            bad = value and name not in ("frames_tx", "frames_rx")
            rows.append([name.replace("_", " "), Text(str(value), "bold yellow" if bad else "")])
        return _block(f"link ({self.desk.backend})", self._tables["link"], rows)


def _block(title: str, table: AlignedRows, rows: list[list[Cell]]) -> list[Text]:
    """A title over rows of a name and its value, the values right-aligned: its lines."""
    return [_title(title), *table.lines(rows)]


@functools.lru_cache(maxsize=16)
def _title(title: str) -> Text:
    """A block's title line, bold (a span: a line's own style is not drawn by ``LiveLines``);
    the very line each time, as it reads the same."""
    return Text(title, spans=[Span(0, len(title), "bold")])


def _pct(duty: float, width: int = 0) -> str:
    """A duty in %, signed; a closed valve reads +0.0, never −0.0 (a polarity of −1 on 0)."""
    return f"{duty + 0.0:+{width or ''}.1f}"


def _share(busy_s: float, elapsed_s: float) -> str:
    """The share of the period the loop's work takes (the thesis: under half the CPU at 1 ms)."""
    return f"{100.0 * busy_s / elapsed_s:.1f} %" if elapsed_s > 0 else "–"


def _supply(mpa: float, machine: Machine) -> Text:
    """The hydraulic supply pressure, yellow once it has sagged 5 % below the nominal."""
    if not math.isfinite(mpa):
        return Text("not measured", "dim")
    nominal = machine.plant.get("supply_mpa", math.nan)
    sagged = math.isfinite(nominal) and mpa < 0.95 * nominal
    return Text(f"{mpa:.2f} MPa", "bold yellow" if sagged else "")


def _num(value: float, unit: str, spec: str = "10.3f") -> str:
    return f"{value:{spec}} {unit}".rstrip() if math.isfinite(value) else "–"
