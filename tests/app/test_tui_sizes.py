"""Every tab at 80×24, 120×36 and 160×48: what the operator needs on it is on the screen,
whole (or scrolled into view where the tab scrolls), with room to be read: every tab on the
tab bar, the header's lines uncut (the latest event ends at a word), the Moves tab's kinds,
form, buttons, preview, progress and result table; Status' names, values and limit bars and
its loop values one line each; the Positions' pose; the Scope's and the Runs' plots with
rows to read; six joints previewed at 160×48 each in its own panel with a curve, none
overlapping. One app goes through the three sizes (the terminal resized), as an operator's
would."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.text import Text
from textual.errors import NoWidget
from textual.geometry import Region
from textual.widget import Widget
from textual.widgets import DataTable, OptionList
from textual.widgets._tabbed_content import ContentTab

from app.event_log import LogEntry
from app.plotting.strips import MIN_ROWS
from app.tabs.runs import RunsTab
from app.tabs.status import FULL_WIDTH, StatusTab
from app.tui import TABS, ServodeskApp
from app.widgets.fields import NumberField
from app.widgets.figure_plot import FigurePlot
from app.widgets.live_text import LiveText
from app.widgets.scope import ScopePlot
from control.recorder import Run, save_run
from hw.machine import load_machine

SIZES = ((80, 24), (120, 36), (160, 48))
BRAILLE = range(0x2801, 0x2900)
PLOT_ROWS = {"scope-position": 5, "scope-duty": 2}  # a Scope plot's rows of curve
LONG_EVENT = ("the hydraulic supply sagged below its nominal pressure while Up/Down held its "
              "end, and the operator was asked to check the accumulator")
# the widgets each tab is for (the Moves tab's preview and the Runs plot are checked drawn)
ESSENTIAL = {
    "jog": ("#jog-table",),
    "moves": ("#move-kinds", "#move-forms", "#move-run", "#move-abort", "#feed-hold",
              "#move-preview-title",
              "#move-preview", "#move-progress", "#move-state", "#move-result"),
    "scope": ("#scope-bar", *(f"#scope-joint-{j}" for j in range(6))),
    "status": ("#status-joints", "#status-pose", "#status-loop", "#status-link"),
    "tuning": ("#tuning-which", "#tuning-joints", "#tuning-common", "#tuning-files"),
    "runs": ("#runs-table", "#runs-bar", "#runs-plot"),
    "latency": ("#latency-fresh", "#latency-tables", "#latency-thesis"),
    "identify": ("#identify-joint", "#identify-run", "#identify-ff", "#identify-apply",
                 "#identify-model", "#identify-plot"),
    "positions": ("#positions-table", "#positions-speed", "#positions-here",
                  "#positions-state"),
    "log": ("#log-file", "#log-table"),
    "program": ("#program-path", "#program-table", "#program-state", "#program-problems"),
}


def a_saved_run(data_dir: Path) -> None:
    """A step of Up/Down in the data directory, for the Runs tab to plot."""
    machine = load_machine("unimate2000b")
    t = np.arange(2000) * machine.sample_time_s
    desired = np.zeros((2000, 6))
    desired[t >= 0.1, 2] = 5.0
    actual = desired.copy()
    actual[:, 2] = np.where(t >= 0.1, 5.0 * (1 - np.exp(-(t - 0.1) / 0.1)), 0.0)
    save_run(Run.from_machine(machine, "step", "complete", {}, t, desired, actual,
                              np.zeros_like(desired)), data_dir)


async def in_view(widget: Widget, pilot) -> Region:
    """``on_screen``, scrolled into view first if it is not whole on the screen already."""
    try:
        return on_screen(widget)
    except (AssertionError, NoWidget):
        widget.scroll_visible(animate=False, immediate=True)
        await pilot.pause()
        return on_screen(widget)


def on_screen(widget: Widget) -> Region:
    """Where ``widget`` is drawn on the screen, after scrolling it into view; it must be
    there whole (its region inside every container's clip) and not empty."""
    screen = widget.screen
    geometry = screen.find_widget(widget)
    region = geometry.region
    assert region.width > 0 and region.height > 0, f"{widget!r} has no room: {region}"
    assert geometry.clip.contains_region(region), f"{widget!r} clipped: {region} in {geometry.clip}"
    assert screen.region.contains_region(region), f"{widget!r} off the screen: {region}"
    return region


async def joints_whole(tui, app: ServodeskApp, selector: str) -> None:
    """A tab's table of joints (Jog's, Status'): nothing cut short, a limit bar on each
    joint's row, and its position among the row's numbers."""
    table = app.query_one(selector, LiveText)
    await tui.until(lambda: "Swivel" in tui.text(table), what=f"the table {selector}")
    text = tui.text(table)
    assert "…" not in text, text
    here = app.client.status().position
    for j, joint in enumerate(app.machine.joints):
        (row,) = [r for r in text.splitlines() if f" {joint.name} " in f" {r.strip()} "]
        assert row.count("├") == 1 and row.rstrip().endswith("┤"), row
        numbers = [float(w) for w in row.split() if w[-1].isdigit()
                   and w.lstrip("+-").replace(".", "", 1).isdigit()]
        assert any(abs(v - here[j]) < 0.2 for v in numbers), row  # its position


def braille(plot: FigurePlot, region: tuple[int, int, int, int]) -> int:
    """How many braille cells (curves) one panel of ``plot`` shows."""
    x, y, w, h = region
    rows = [plot.render_line(row).text[x:x + w] for row in range(y, y + h)]
    return sum(ord(c) in BRAILLE for row in rows for c in row)


@contextlib.contextmanager
def at(size: tuple[int, int]) -> Iterator[None]:
    """Name the size in a failure of the checks inside."""
    try:
        yield
    except AssertionError as failure:
        raise AssertionError(f"at {size[0]}×{size[1]}: {failure}") from failure


async def resize(tui, app: ServodeskApp, pilot, size: tuple[int, int]) -> None:
    """The terminal resized to ``size``, and the screen laid out for it."""
    await pilot.resize_terminal(*size)
    await tui.until(lambda: app.screen.size == size and app.query_one("#header-health").size.width
                    > 0, what=f"the screen at {size}")
    await pilot.pause()


def tab_bar_whole(app: ServodeskApp) -> None:
    """F1…F11 each on the tab bar, whole, with the Jog tab chosen (no scrolling to reach one)."""
    tabs = list(app.query(ContentTab))
    assert len(tabs) == len(TABS)
    for i, tab in enumerate(tabs):
        assert str(tab.label).startswith(f"F{i + 1} "), tab.label
        on_screen(tab)


async def header_whole(tui, app: ServodeskApp) -> None:
    """The header's three lines as they were composed, none cut by the screen's edge; a
    latest event too long for the line ends with "…" after a whole word."""
    header = app.header
    identity = app.query_one("#header-identity", LiveText)
    await tui.until(lambda: "notice: the" in identity.text,
                    what=lambda: f"the long event in the header: {identity.text!r}")
    for line in ("#header-identity", "#header-health", "#header-loop"):
        widget = app.query_one(line, LiveText)
        shown = tui.text(widget).rstrip()
        assert shown == widget.text.rstrip(), f"{line} cut: {shown!r} of {widget.text!r}"
    shown = tui.text(identity).rstrip()
    words = set(f"servodesk {header.machine_title} backend {header.backend} latest ▸ · "
                f"{header.latest.line()}".split())
    assert shown.endswith("…"), shown
    assert set(shown[:-1].split()[-4:]) <= words, f"a word cut: {shown!r}"


def status_rows_whole(app: ServodeskApp) -> None:
    """Status' pose, loop and link: each value on its row, with big numbers in them too (a
    late loop, a long move)."""
    tab = app.query_one(StatusTab)
    status = replace(app.client.status(), late_last_us=2735.2, late_max_us=12735.0,
                     compute_last_us=1234.5, compute_max_us=12345.0, move_id=123,
                     move_done=60000, move_total=120000)
    console = app.console
    full = app.query_one("#status-joints").size.width >= FULL_WIDTH  # as the tab chooses
    for selector, lines, rows in (
            ("#status-pose", tab._pose(status, full), 7),
            ("#status-loop", tab._loop(status), 12),
            ("#status-link", tab._link(status), 1 + len(status.link))):
        widget = app.query_one(selector, LiveText)
        renderable = Text("\n").join(lines)
        shown, whole = (["".join(s.text for s in line).rstrip()
                         for line in console.render_lines(
                             renderable, console.options.update_width(width), pad=False)]
                        for width in (widget.size.width, 500))
        assert shown == whole, (f"{selector} wrapped or cut at {widget.size.width} columns: "
                                + " / ".join(shown))
        assert len(shown) == rows


def pose_shown(tui, app: ServodeskApp) -> None:
    """Each position's pose on the screen beside its joints."""
    table = app.query_one("#positions-table", DataTable)
    text = tui.text(table)
    tab = app.tab("positions")
    for p in tab.book.positions:
        for v in (*p.joints, *app.model.pose(np.array(p.joints))):
            assert f"{v:.1f}" in text, f"{p.name}: {v:.1f} not on the screen:\n{text}"


async def scope_plots_tall(app: ServodeskApp, pilot) -> None:
    """Every joint's Scope plots with rows to read (at 80×24 six joints shared 17 rows)."""
    for plot in app.tab("scope").query(ScopePlot):
        region = await in_view(plot, pilot)
        rows = next(n for cls, n in PLOT_ROWS.items() if plot.has_class(cls))
        assert region.height >= rows + 2, f"{plot.parent.id} {plot.classes}: {region}"


def test_every_tab_shows_what_it_is_for(tui) -> None:
    """Every tab at each size, the Moves tab with a multi-step of all six joints in its form
    (``six_previewed``: checked on the app that goes through the sizes, not on one of its
    own)."""
    a_saved_run(tui.data_dir)

    async def scenario() -> None:
        app = tui.app(build_behind=True)  # every tab is opened
        async with app.run_test(size=SIZES[-1]) as pilot:
            status = await tui.ready(app, pilot)
            app.record_event(LogEntry(time.time(), "notice", LONG_EVENT))
            await pilot.press("f2")
            kinds = app.query_one("#move-kinds", OptionList)
            kinds.highlighted = next(i for i in range(kinds.option_count)
                                     if str(kinds.get_option_at_index(i).prompt) == "Multi-step")
            await pilot.pause()
            for j, q in enumerate(status.position):
                app.query_one(f"#form-multi_step #target{j}", NumberField).text = f"{q + 3:.1f}"
            for size in SIZES:
                await resize(tui, app, pilot, size)
                with at(size):
                    await show(tui, app, pilot, "f1", app.tab("jog"))
                    tab_bar_whole(app)
                    await header_whole(tui, app)
                    await every_tab(tui, app, pilot, size)

    asyncio.run(scenario())


async def show(tui, app: ServodeskApp, pilot, key: str, tab: Widget) -> None:
    """``key`` delivered as the terminal's driver delivers it (as Pilot's ``press`` does), then
    a wait for its condition, ``tab`` shown, and a pause: the screen laid out for it, as
    before. ``press`` waited for an idle app twice more after each key, and sent each of the
    screen's 425 widgets a message to wait for: 0.2 s a key, a tenth of the test's CPU."""
    tui.post_key(app, key)
    await tui.until(lambda: tab.visible_now, what=f"the tab of {key} shown")
    await pilot.pause()


async def every_tab(tui, app: ServodeskApp, pilot, size: tuple[int, int]) -> None:
    for i, (name, _) in enumerate(TABS):
        tab = app.tab(name)
        await show(tui, app, pilot, f"f{i + 1}", tab)
        if name == "runs":
            runs = app.query_one(RunsTab)
            await tui.until(lambda runs=runs: runs.infos, what="the run listed")
            if runs.run is None:
                runs.open_latest()
            await tui.until(lambda runs=runs: runs.run is not None, what="run open")
            runs.view = 0
            runs.draw()
            await pilot.pause()
        for selector in ESSENTIAL[name]:
            await in_view(tab.query_one(selector), pilot)
        if name == "jog":
            await joints_whole(tui, app, "#jog-table")
            pose = tui.text(app.query_one("#jog-pose", LiveText))
            # γ β α whole (then, near a singularity, its warning as far as it fits)
            assert "…" not in pose and pose.split("⚠")[0].count("°") == 3, pose
        if name == "moves":  # each kind on one line, the feed hold's label whole
            assert "Multi-step" in tui.text(app.query_one("#move-kinds"))
            assert app.query_one("#feed-hold").region.height == 1
            await six_previewed(tui, app.query_one("#move-preview", FigurePlot), size)
        if name == "scope":
            await scope_plots_tall(app, pilot)
        if name == "latency":  # every bin's span, count and share whole
            total = app.query_one("#latency-total")
            await tui.until(lambda total=total: "0–5" in tui.text(total),
                            what="the histogram")
            assert "…" not in tui.text(total), tui.text(total)
        if name == "status":
            await joints_whole(tui, app, "#status-joints")
            status_rows_whole(app)
        if name == "positions":
            pose_shown(tui, app)
        if name == "runs":
            plot = app.query_one("#runs-plot", FigurePlot)
            await tui.until(lambda plot=plot: plot.drawn is not None, what="run plot")
            assert all(braille(plot, r) for r in plot.panel_regions())
            assert all(h >= MIN_ROWS for _, _, _, h in plot.panel_regions())
            runs.view = runs.views().index("plotdata Up/Down")  # four panels
            runs.draw()
            await pilot.pause()
            assert plot.drawn is not None and len(plot.drawn.panels) >= 2
            assert all(braille(plot, r) for r in plot.panel_regions())


async def six_previewed(tui, plot: FigurePlot, size: tuple[int, int]) -> None:
    """A multi-step of all six joints: at 160×48 six panels with a height and a curve each,
    side by side without overlapping; on a smaller screen at least the one-panel summary of
    every joint (never an empty plot)."""
    await tui.until(lambda: plot.drawn is not None and len(plot.drawn.panels) in (1, 6)
                    and plot.figure is not None and len(plot.figure.panels) == 6
                    and plot.size.width > 0, what="the six joints previewed")
    on_screen(plot)
    regions = plot.panel_regions()
    if size == (160, 48):
        assert plot.drawn is plot.figure and len(regions) == 6
    for k, (x, y, w, h) in enumerate(regions):
        assert h >= MIN_ROWS + 2 and w > 0
        assert braille(plot, (x, y, w, h)), f"panel {k} shows no curve"
        for other in regions[k + 1:]:
            assert not Region(x, y, w, h).overlaps(Region(*other))
    if plot.drawn is not plot.figure:  # one panel: every joint's share of its move
        assert len(plot.drawn.panels[0].lines) == 6
