"""What the idle TUI costs, as behaviour: a widget whose content did not change is not drawn
again, the status is drawn at most ten times a second, and the tabs not shown are not built
before the first frame. (Its CPU and times are figures: ``benchmarks/ui.py --tmux``.)"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import shlex
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from rich.style import Style
from rich.text import Text
from textual._compositor import Compositor
from textual._styles_cache import StylesCache
from textual.app import App, ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

import app.tui
from app.plotting import braille
from app.plotting.braille import Rows, Trace, render
from app.plotting.strips import plot_strips
from app.screens.live import ChangedRowsCompositor, LiveScreen
from app.tabs.status import StatusTab
from app.tui import ServodeskApp
from app.widgets.direct_lines import DirectLines
from app.widgets.live_text import LiveLines, LiveText
from app.widgets.scope import ScopePlot
from tests.app.conftest import Tui
from tests.app.terminal import (
    HEIGHT,
    REPO,
    START_S,
    TMUX,
    WIDTH,
    Terminal,
    kill_server,
    tmux,
)

APP_DIR = Path(app.tui.__file__).parent

STATUS_HZ = 10.0
OBSERVED_TICKS = 20  # header refreshes watched: two seconds at 10 Hz


def count_renders(widget: Widget) -> list[int]:
    """Count the lines Textual draws of ``widget`` (it asks for a line only when the widget,
    or that line of it, was refreshed: its other lines come from its cache); of a widget that
    hands the screen its lines itself (``DirectLines``: the live screen asks it only for the
    rows that changed), the lines it hands over."""
    drawn = [0]
    if isinstance(widget, DirectLines):
        render_lines: Callable[[Region], list[Strip]] = widget.render_lines

        def handed(crop: Region) -> list[Strip]:
            drawn[0] += crop.height
            return render_lines(crop)

        widget.render_lines = handed  # type: ignore[method-assign]
        return drawn
    render_line: Callable[[int], Strip] = widget.render_line

    def counted(y: int) -> Strip:
        drawn[0] += 1
        return render_line(y)

    widget.render_line = counted  # type: ignore[method-assign]
    return drawn


async def watch_ticks(app: ServodeskApp, ticks: int) -> float:
    """Wait until the header has shown ``ticks`` new statuses; the seconds that took."""
    started = time.monotonic()
    seen, last = 0, app.header.status
    deadline = started + 30
    while seen < ticks:
        assert time.monotonic() < deadline, "the header stopped showing new statuses"
        await asyncio.sleep(0.01)
        if app.header.status is not last:
            seen, last = seen + 1, app.header.status
    return time.monotonic() - started


def count_draws(app: ServodeskApp) -> dict[str, int]:
    """Count the screen's updates and the lines they draw, of every widget shown, and the
    lines drawn of containers (widgets with children)."""
    seen = {"updates": 0, "lines": 0, "container lines": 0}
    screen = app.screen
    update = screen._compositor_refresh

    def counted_update() -> None:
        seen["updates"] += 1
        update()

    screen._compositor_refresh = counted_update  # type: ignore[method-assign]
    for widget in screen.walk_children(with_self=True):
        render_lines = widget.render_lines

        def counted(crop: Region, render_lines: Callable[[Region], list[Strip]] = render_lines,
                    container: bool = bool(widget.children)) -> list[Strip]:
            seen["lines"] += crop.height
            seen["container lines"] += crop.height if container else 0
            return render_lines(crop)

        widget.render_lines = counted  # type: ignore[method-assign]
    return seen


def test_idle_jog_status_and_scope_draw_and_make_only_what_changed(tui) -> None:
    """One app, idle, watched for ``OBSERVED_TICKS`` header ticks on Jog, then on Status,
    then on the Scope, with every counter of its tab on at once (these were nine tests, each
    with an app of its own, twelve such windows in all; each claim is checked as it was, by
    its own assert, after its tab's window: ``idle_jog``, ``idle_status``, ``live_scope``)."""
    app = tui.app(lockstep=False)

    async def scenario() -> None:
        async with app.run_test(size=(160, 48)) as pilot:
            await tui.ready(app, pilot)
            assert app.sampler is not None
            assert app.sampler.period == pytest.approx(1 / 50)  # Jog
            await idle_jog(app, pilot)
            await idle_status(app, pilot)
            await live_scope(app, pilot)

    asyncio.run(scenario())


async def idle_jog(app: ServodeskApp, pilot) -> None:
    """Idle on Jog:

    An idle tick changes the header's loop line (its tick count). The screen draws the rows
    that change is on, of the widgets it is in, in one update a tick, and no container under
    them (the terminal is sent the widgets' cells in front). Textual's own compositor drew
    every line of every widget whose parent's area met the box around the changes (the
    screen's 48, the tab bar's 44, ...: 111 lines a tick on Jog); the first live screen drew
    the containers behind (6 lines a tick on Jog).

    The jog pad and the min-PWM note, unchanged, are not drawn again; the loop line, which
    changes every status, is drawn at most at 10 Hz.

    The client's event thread waits on the channel, woken by an event or the controller's
    end closing; idle it wakes ten times a second to look for a controller gone without
    closing it. The old thread woke every 10 ms: a hundred times a second (twice that counted
    here when it waited for the interpreter's lock), half a percent of a core on every tab."""
    await pilot.press("f1")
    await watch_ticks(app, 5)  # the tab's first frames drawn
    pad = app.query_one("#jog-pad")
    note = app.query_one("#jog-dead-band", LiveText)
    loop = app.query_one("#header-loop", LiveText)
    shown = (pad.render().plain, note.text)
    pad_drawn, note_drawn, loop_drawn = (count_renders(w) for w in (pad, note, loop))
    seen = count_draws(app)
    events = next(t for t in threading.enumerate() if t.name == "servodesk-events")
    before, started = thread_wakeups(events), time.monotonic()
    elapsed = await watch_ticks(app, OBSERVED_TICKS)
    rate = (thread_wakeups(events) - before) / (time.monotonic() - started)
    assert 0 < seen["lines"] <= 4 * OBSERVED_TICKS, ("f1", seen)
    assert seen["container lines"] == 0, ("f1", seen)
    assert seen["updates"] <= OBSERVED_TICKS + 3, ("f1", seen)
    drawn = pad_drawn[0], note_drawn[0], loop_drawn[0]
    assert (pad.render().plain, note.text) == shown  # nothing pressed: the same
    assert drawn[0] == 0, f"the jog pad: {drawn[0]} lines drawn again unchanged"
    assert drawn[1] == 0, f"the min-PWM note: {drawn[1]} lines drawn again unchanged"
    # the loop line changes every status (its tick count): drawn, at most at 10 Hz
    assert 0 < drawn[2] <= STATUS_HZ * elapsed + 2, (drawn[2], elapsed)
    assert rate <= 40, f"the event thread woke {rate:.0f} times a second, idle"


async def idle_status(app: ServodeskApp, pilot) -> None:
    """Idle on Status (F4):

    A tick changes the header's loop line, a few numbers of the joints and the loop: the
    screen draws the rows those changes are on, of the widgets they are in, in one update a
    tick, and no container under them. Textual's own compositor drew 430 lines a tick here,
    and the old Status drew the header and the tab in two updates a tick; the first live
    screen drew the containers behind (108 lines a tick).

    The joints' and the loop's blocks are drawn at most ten times a second, the link's
    (unchanged: the simulator's link counters stay at zero) not again.

    A block is made again only when what it is made of changed: the link's is made once, not
    ten times a second (the old tab made every block every tick and compared the lines it
    drew).

    Every joint's glitch count climbs each tick, so the joints' block changes ten times a
    second; a line of it that reads as before is the very line shown before (its title, the
    columns' heads, a joint at rest), and a joint's row whose count changed within its width
    has the new digits written into its line: no row is laid out again whole but when a count
    gains a digit. The old tab laid out the whole table again every tick.

    On the header's tick the tab shows the status the header was given (the sampler's
    newest), in the same screen update; the old tab read and decoded a status of its own
    from shared memory each tick.

    Each block is made as its lines and shown so (``show_rows``): the old tab joined the
    lines into one Text that the widget split into lines again, for the joints and the loop
    every tick (a fifth of the tab's own CPU).

    Its blocks have no border, padding or tint: their lines go to the screen as their widgets
    draw them, not through Textual's styles cache (whose work a call cost more than the lines
    that changed: the old widgets went through it three times a tick), and those lines are
    the very lines the styles cache gives of them."""
    await pilot.press("f4")
    joints, loop, link = (app.query_one(f"#status-{name}", LiveText)
                          for name in ("joints", "loop", "link"))
    for block, shows in ((joints, "Swivel"), (loop, "controller time"), (link, "crc errors")):
        await Tui.until(lambda block=block, shows=shows: shows in Tui.text(block),
                        what=f"{shows} in {block.id}")
    await watch_ticks(app, 5)  # the tab's first frames drawn
    widgets = [w for w in app.screen.query(LiveLines) if w.region.area]
    assert widgets, "f4"
    seen = count_draws(app)
    link_shown, loop_before = Tui.text(link), Tui.text(loop)
    drawn = {block.id: count_renders(block) for block in (joints, loop, link)}
    made: list[int] = []
    link_block = StatusTab._link

    def link_made(self: StatusTab, status: object) -> list[Text]:
        made.append(1)
        return link_block(self, status)  # type: ignore[arg-type]

    shown: list[list[Text]] = []
    show_rows = LiveLines.show_rows

    def recorded(self: LiveLines, rows: list[Text]) -> None:
        if self is joints:
            shown.append(list(rows))
        show_rows(self, rows)

    split: list[str] = []
    show = LiveLines.show

    def split_again(self: LiveLines, renderable: object) -> None:
        if isinstance(renderable, Text) and (self.id or "").startswith("status-"):
            split.append(self.id or "")
        show(self, renderable)  # type: ignore[arg-type]

    cached: list[Widget] = []
    render_widget = StylesCache.render_widget

    def through_cache(self: StylesCache, widget: Widget, crop: Region) -> list[Strip]:
        cached.append(widget)
        return render_widget(self, widget, crop)

    client = app.client
    read: list[int] = []
    status = client.status

    def read_again() -> object:
        read.append(1)
        return status()

    table = app.tab("status")._tables["joints"]
    laid_out = table.laid_out
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(StatusTab, "_link", link_made)
        patch.setattr(LiveLines, "show_rows", recorded)
        patch.setattr(LiveLines, "show", split_again)
        patch.setattr(StylesCache, "render_widget", through_cache)
        patch.setattr(client, "status", read_again)  # the sampler reads its own reference
        elapsed = await watch_ticks(app, OBSERVED_TICKS)
    # the screen's updates
    assert 0 < seen["lines"] <= 30 * OBSERVED_TICKS, ("f4", seen)
    assert seen["container lines"] == 0, ("f4", seen)
    assert seen["updates"] <= OBSERVED_TICKS + 3, ("f4", seen)
    # at most ten times a second, and only what changed
    counts = {name: count[0] for name, count in drawn.items()}
    for block in (joints, loop):  # the sample count, the raw words: every status
        assert 0 < counts[block.id] <= (STATUS_HZ * elapsed + 2) * block.size.height, (
            block.id, counts, elapsed)
    assert Tui.text(link) == link_shown  # the simulator's link counters stay at zero
    assert counts[link.id] == 0, f"the link block: {counts[link.id]} lines drawn unchanged"
    # a block that reads the same is not made again
    assert len(made) <= 1, f"the link block made {len(made)} times unchanged"
    assert "crc errors" in Tui.text(link)
    # only the lines and cells that changed are made again
    changed, made_again = 0, []
    for before, after in itertools.pairwise(shown):
        for old, new in zip(before, after, strict=True):
            if old.plain != new.plain or old.spans != new.spans:
                changed += 1
            elif old is not new:
                made_again.append(old.plain.split()[0])
    assert len(shown) >= OBSERVED_TICKS - 2, len(shown)
    assert changed >= OBSERVED_TICKS // 2, "the glitch counts did not climb"
    assert not made_again, f"lines reading as before made again: {made_again[:8]}"
    assert table.laid_out - laid_out <= app.machine.n_joints, (
        f"{table.laid_out - laid_out} rows laid out again in {OBSERVED_TICKS} ticks")
    # shown by its lines, not split each tick
    assert Tui.text(loop) != loop_before  # the sample count moved on
    assert not split, f"blocks split into lines again: {sorted(set(split))}"
    # to the screen as drawn, and the same as through the styles cache
    drawn_directly(widgets, cached, "f4")
    # the status the header shows, not one read again
    assert not read, f"the tab read the status {len(read)} times itself"
    await watch_ticks(app, 1)
    sample = next(line for line in Tui.text(loop).splitlines() if "sample" in line)
    assert int(sample.split()[-1]) == app.header.status.tick


def drawn_directly(widgets: list, cached: list[Widget], key: str) -> None:
    """None of ``widgets`` went through the styles cache (``cached``): each draws its lines
    directly, and they are the very lines the styles cache gives (``key``: the tab's)."""
    through = {str(w) for w in cached if w in widgets}
    assert not through, f"{key}: through the styles cache: {sorted(through)}"
    assert all(w.direct() for w in widgets), key
    for widget in widgets:
        whole = Region(0, 0, *widget.size)
        assert widget.render_lines(whole) == Widget.render_lines(widget, whole), widget


async def live_scope(app: ServodeskApp, pilot) -> None:
    """On the Scope (F3), then back to Status:

    The sampler reads the status 200 times a second for the Scope's plots; on the other
    tabs 50 are enough (the Scope's past is then drawn from those), at a quarter of the CPU.
    The old sampler read at 200 Hz on every tab.

    Its plots have no border, padding or tint: their lines go to the screen as drawn, not
    through Textual's styles cache (the old ones went through it seven times a frame), and
    are the very lines the styles cache gives of them.

    A frame rasters the traces of its twelve plots (six joints' desired, actual and duty over
    one time axis) in one pass of array operations, and each plot shows what it would drawn
    alone. The old frame rastered them trace by trace: eighteen passes a frame, most of the
    Scope's CPU."""
    assert app.sampler is not None
    await pilot.press("f3")
    scope = app.tab("scope")
    await Tui.until(lambda: scope.visible_now, what="the Scope shown")
    assert app.sampler.period == pytest.approx(1 / 200)
    samples = len(app.history)
    await watch_ticks(app, 5)
    widgets = [w for w in app.screen.query(ScopePlot) if w.region.area]
    assert widgets, "f3"
    cached: list[Widget] = []
    render_widget = StylesCache.render_widget

    def through_cache(self: StylesCache, widget: Widget, crop: Region) -> list[Strip]:
        cached.append(widget)
        return render_widget(self, widget, crop)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(StylesCache, "render_widget", through_cache)
        await watch_ticks(app, OBSERVED_TICKS)
    drawn_directly(widgets, cached, "f3")
    await Tui.until(lambda: len(app.history) >= samples + 100, timeout=20,
                    what="a hundred samples more")
    passes: list[int] = []
    columns_many = braille.columns_many

    def counted(x: np.ndarray, ys: np.ndarray, *args: object) -> tuple[np.ndarray, np.ndarray]:
        passes.append(ys.shape[1])
        return columns_many(x, ys, *args)  # type: ignore[arg-type]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(braille, "columns_many", counted)
        scope.refresh_live()
    assert passes == [18], passes  # desired, actual and duty of six joints at once
    for plot in scope.query(ScopePlot):
        alone = plot_strips(plot._traces, plot._x_range, plot._y_range, plot._title,
                            plot.size.width, plot.size.height, app.console,
                            zero_line=plot._zero_line, x_labels=plot._x_labels)
        assert plot._lines == alone
    await pilot.press("f4")
    await Tui.until(lambda: app.tab("status").visible_now, what="the Status shown")
    assert app.sampler.period == pytest.approx(1 / 50)


class Nested(App[None]):
    """Containers in containers, side by side and docked, as the tabs' screen has them."""

    CSS = """
    #top { height: 3; } #side { dock: right; width: 12; }
    LiveLines { height: 4; } Horizontal LiveLines { width: 1fr; }
    #boxed { border: round red; padding: 0 1; height: auto; } Horizontal { height: 5; }
    """

    def get_default_screen(self) -> LiveScreen:
        return LiveScreen(id="_default")

    def compose(self) -> ComposeResult:
        yield LiveLines(id="top")
        yield LiveLines(id="side")
        with VerticalScroll():
            with Vertical(id="boxed"):
                yield LiveLines(id="a")
                with Horizontal():
                    yield LiveLines(id="b")
                    yield LiveLines(id="c")
            yield LiveLines(id="d")


def test_the_changed_rows_compositor_sends_what_textuals_sends() -> None:
    """For random changes of random lines, and of a container with a border showing around
    its children, the live screen's partial update sends the terminal the very bytes Textual's
    compositor sends for them (it only draws less)."""
    rng = np.random.default_rng(7)

    def lines(n: int) -> Text:
        return Text("\n".join(f"{rng.integers(10**9):>{rng.integers(9, 30)}} row {k}"
                              for k in range(n)), style=str(rng.choice(["", "bold", "red"])))

    async def scenario() -> None:
        app = Nested()
        async with app.run_test(size=(60, 20)) as pilot:
            widgets = list(app.query(LiveLines))
            for widget in widgets:
                widget.show(lines(4))
            await pilot.pause()
            screen, compositor = app.screen, app.screen._compositor
            # a Textual whose compositor the live one does not fit draws with its own
            assert isinstance(compositor, ChangedRowsCompositor), "Textual changed: see live.py"
            boxed = app.query_one("#boxed")
            for _ in range(200):
                changed = [w for w in widgets if rng.random() < 0.4] or widgets[:1]
                for widget in changed:
                    widget.show(lines(4))
                if rng.random() < 0.2:  # its border's rows and columns, under and beside all
                    boxed.refresh(Region(0, int(rng.integers(0, 6)), 30, 2))
                    changed.append(boxed)
                compositor.update_widgets(set(changed))
                regions = set(compositor._dirty_regions)
                live = compositor.render_partial_update()
                compositor._dirty_regions.update(regions)
                textual = Compositor.render_partial_update(compositor)
                assert (live is None) == (textual is None)
                if live is not None:
                    assert (live.render_segments(app.console)
                            == textual.render_segments(app.console)), regions
                screen._dirty_widgets.clear()

    asyncio.run(scenario())


class FirstFrame(ServodeskApp):
    """Notes which tabs are built when the first frame has been drawn."""

    # the stylesheets are beside app/tui.py, not beside this file
    CSS_PATH: ClassVar = [str(APP_DIR / path) for path in ServodeskApp.CSS_PATH]
    built_at_first_frame: list[str] | None = None

    def on_mount(self) -> None:  # before ServodeskApp's own on_mount
        self.call_after_refresh(self._first_frame)

    def _first_frame(self) -> None:
        self.built_at_first_frame = [name for name, tab in self.tabs.items()
                                     if tab.is_attached]


def test_tabs_not_shown_are_not_built_before_the_first_frame(tui) -> None:
    async def scenario() -> None:
        app = FirstFrame("unimate2000b", "sim", None, tui.data_dir,
                         client_options={"heartbeat_timeout_s": 2.0})
        async with app.run_test(size=(160, 48)) as pilot:
            await tui.until(lambda: app.built_at_first_frame is not None, what="a first frame")
            assert app.built_at_first_frame == ["jog"]
            await tui.ready(app, pilot)  # live, then every tab built, one at a time
            tui.post_key(app, "f3")
            scope = app.tab("scope")
            await tui.until(lambda: scope.visible_now, what="the Scope tab shown")
            await tui.no_tab_half_built(app)

    asyncio.run(scenario())


def test_a_tab_chosen_while_it_is_being_built_shows_whole(tui) -> None:
    """The background's build of the Moves tab under way (mounting) when F2 chooses it: the
    tab is shown once it is mounted, with its staged parts (the forms, the preview). It was
    shown at once, before its mount hid those parts, so nothing revealed them: in tmux the
    Moves tab stayed a bare menu for good when F2 came right after the screen went live."""

    async def scenario() -> None:
        app = FirstFrame("rig", "sim", None, tui.data_dir,
                         client_options={"heartbeat_timeout_s": 2.0})
        async with app.run_test(size=(160, 48)) as pilot:
            await tui.until(lambda: app.built_at_first_frame is not None, what="a first frame")
            moves = app.tab("moves")
            assert not moves.is_attached
            building = asyncio.create_task(app._build("moves"))  # as the background does
            await tui.until(lambda: moves.is_attached, what="Moves being mounted")
            app._activate("moves")  # F2 meanwhile
            await building
            parts = [moves.query_one(s) for s in type(moves).LATER]
            await tui.until(lambda: moves.visible_now
                            and all(p.styles.visibility == "visible" for p in parts),
                            what=lambda: f"Moves' parts: {[p.styles.visibility for p in parts]}")
            await pilot.pause()
            await tui.no_tab_half_built(app)

    asyncio.run(scenario())


# what a client that starts its own controller never runs: a service's link and its
# rendezvous, the controller process's own code, the move planners the first tab does not use
NOT_AT_START = ("control.attached", "control.rendezvous", "control.rt.process",
                "control.rt.loop", "control.motion.form_plans")


def test_an_app_on_its_own_controller_imports_only_what_its_first_frame_and_start_run(
        tui) -> None:
    """A fresh interpreter (this one has imported everything): the app started on a controller
    of its own. When its first frame has been drawn, the modules of app.tabs loaded are the Jog
    tab's alone: the old app.tui imported every tab's module (their numpy, plotting and forms)
    before anything was drawn. Once the controller is up too, none of ``NOT_AT_START`` is
    loaded: the old control.client imported them all before it could start the controller, and
    the screen after it. (One interpreter for both: each was a start of its own, 0.7 s; ``tui``
    is taken for its data directory.)"""
    script = f"""
import asyncio, json, sys
from pathlib import Path
import app.tui
from app.tui import TABS, ServodeskApp

class Live(ServodeskApp):
    CSS_PATH = [str(Path(app.tui.__file__).parent / path) for path in ServodeskApp.CSS_PATH]
    loaded = None

    def on_mount(self):
        self.call_after_refresh(self.first_frame)

    def first_frame(self):
        self.loaded = sorted(m for m in sys.modules if m.startswith("app.tabs."))

async def main():
    app = Live("unimate2000b", "sim", None, {str(tui.data_dir)!r},
               client_options={{"heartbeat_timeout_s": 2.0}})
    async with app.run_test(size=(160, 48)) as pilot:
        while not (app.loaded is not None and app.client is not None):
            await asyncio.sleep(0.01)
        print(json.dumps({{"loaded": app.loaded, "tabs": [name for name, _ in TABS],
                          "not_at_start": sorted(set({NOT_AT_START!r}) & set(sys.modules))}}))

asyncio.run(main())
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    others = {f"app.tabs.{name}" for name in seen["tabs"] if name != "jog"}
    assert "app.tabs.jog" in seen["loaded"]
    assert not others & set(seen["loaded"]), sorted(others & set(seen["loaded"]))
    assert seen["not_at_start"] == [], "imported by an app on a controller of its own"


@pytest.mark.skipif(TMUX is None, reason="tmux is not installed (apt-get install tmux)")
def test_servodesk_starts_its_controller_before_it_imports_the_screen(tmp_path: Path) -> None:
    """``servodesk`` in a real terminal: when the controller's process is started, Textual is
    not imported yet (the process comes up on the other core while the screen's code loads);
    the screen then goes live on that controller, in reduced speed as the TUI starts it. The
    old start imported the screen, built it, and only then started the controller."""
    record = tmp_path / "at-start.json"
    # an audit hook sees the controller's process start, in the app's own interpreter
    script = f"""
import json, sys

def hook(event, args):
    if event == "control.launch":
        with open({str(record)!r}, "w") as out:
            json.dump({{"textual": "textual" in sys.modules}}, out)

sys.addaudithook(hook)
from app.cli import main
sys.exit(main(["--data-dir", {str(tmp_path / "data")!r}]))
"""
    socket, status = f"servodesk-start-{os.getpid()}", tmp_path / "exit-status"
    command = (f"cd {shlex.quote(str(REPO))} && env -u COLUMNS -u LINES "
               f"PYTHONPATH={shlex.quote(str(REPO))} {shlex.quote(sys.executable)} -c "
               f"{shlex.quote(script)}; echo $? > {shlex.quote(str(status))}")
    try:
        tmux(socket, "start-server", ";", "set-option", "-g", "remain-on-exit", "on", ";",
             "new-session", "-d", "-s", "start", "-x", str(WIDTH), "-y", str(HEIGHT), command)
        term = Terminal(socket, "start", status)
        term.wait(lambda s: " RUN" in s and "mode HOLD" in s and "T1" in s,
                  "a live screen in reduced speed", timeout=START_S)
        assert json.loads(record.read_text()) == {"textual": False}
        term.keys("C-q")
        term.wait(lambda s: term.exit_status() is not None, "the app's exit")
        assert term.exit_status() == 0, term.screen()
    finally:
        kill_server(socket)


def test_a_line_that_changed_repaints_only_its_changed_cells() -> None:
    """A LiveLines line whose numbers changed asks the screen to update those cells, not the
    whole line: the box the screen redraws then leaves out the widgets beside them (Status'
    blocks, the header's lamp). The old LiveLines refreshed the line's whole width."""

    class One(App[None]):
        def compose(self) -> ComposeResult:
            yield LiveLines(id="lines")

    async def scenario() -> None:
        app = One()
        async with app.run_test(size=(80, 4)) as pilot:
            lines = app.query_one(LiveLines)
            lines.show(Text("tick 100  t 1.00 s\nmode HOLD"))
            await pilot.pause()
            asked: list[Region] = []
            refresh = lines.refresh

            def recorded(*regions: Region, **options: object) -> Widget:
                asked.extend(regions)
                return refresh(*regions, **options)  # type: ignore[arg-type]

            lines.refresh = recorded  # type: ignore[method-assign]
            lines.show(Text("tick 107  t 1.07 s\nmode HOLD"))
            assert asked == [Region(7, 0, 9, 1)]  # "7  t 1.07": the first to the last change
            await pilot.pause()
            assert Tui.text(lines).splitlines()[0].startswith("tick 107  t 1.07 s")
            asked.clear()
            lines.show(Text.assemble("tick 107  t 1.07 s\n", ("mode HOLD", "bold")))
            assert asked == [Region(0, 1, 80, 1)]  # a style changed: the whole line

    asyncio.run(scenario())


def test_a_line_whose_few_characters_changed_is_written_into_its_drawn_line() -> None:
    """A LiveLines line that changed only in a few characters, in the same styles, is drawn by
    writing them into the line as last drawn, not by drawing the whole line again (a joint's
    glitch count on Status, the header's sample number); the line drawn is, cell for cell,
    the one a whole drawing gives. The old LiveLines drew every changed line whole."""

    class One(App[None]):
        def compose(self) -> ComposeResult:
            yield LiveLines(id="lines")

    def line(tick: int, glitches: int) -> Text:
        return Text.assemble("tick ", (f"{tick}", "bold"), "  glitches ",
                             (f"{glitches:3d}", "yellow"), ("  ├──●──┤", "green"))

    def cells(strip: Strip) -> list[tuple[str, Style | None]]:
        return [(c, segment.style) for segment in strip for c in segment.text]

    async def scenario() -> None:
        app = One()
        async with app.run_test(size=(60, 3)) as pilot:
            lines = app.query_one(LiveLines)
            lines.show_rows([line(100, 7), Text("mode HOLD")])
            await pilot.pause()
            drawn: list[Text] = []
            render = Text.render

            def counted(self: Text, *args: object, **kwargs: object) -> object:
                drawn.append(self)
                return render(self, *args, **kwargs)

            with pytest.MonkeyPatch.context() as patch:
                patch.setattr(Text, "render", counted)
                for tick in range(101, 140):
                    lines.show_rows([line(tick, tick % 50), Text("mode HOLD")])
                    await pilot.pause(0)  # its messages handled and the screen drawn, unslept
            assert not [t.plain for t in drawn], "lines drawn again whole"
            whole = (Strip(list(line(139, 39).render(app.console)))
                     .adjust_cell_length(lines.size.width).apply_style(lines.rich_style))
            assert cells(lines.render_line(0)) == cells(whole)
            # and through the app's line filters, as Textual's styles cache gives it
            region = Region(0, 0, lines.size.width, 1)
            assert cells(lines.render_lines(region)[0]) == cells(
                Widget.render_lines(lines, region)[0])
            lines.show_rows([line(1000, 39), Text("mode HOLD")])  # longer: drawn whole again
            assert cells(lines.render_line(0)) == cells(
                Strip(list(line(1000, 39).render(app.console)))
                .adjust_cell_length(lines.size.width).apply_style(lines.rich_style))

    asyncio.run(scenario())


def test_a_plot_makes_again_only_the_rows_that_changed() -> None:
    """A live plot keeps its rows as drawn (``braille.Rows``): a frame whose dots are the same
    hands back the very strips of the last one, and a change makes new strips only for the
    rows it reaches, the same as a fresh drawing. The old raster made every row of every plot
    again, 25 times a second on the Scope."""
    x = np.linspace(-10.0, 0.0, 2000)
    flat = np.full(2000, 5.0)
    style = Style(color="cyan")
    drawn = Rows()

    def draw(y: np.ndarray, rows: Rows | None) -> list[Strip]:
        return render([Trace(x, y, style)], (-10.0, 0.0), (0.0, 10.0), 60, 8, drawn=rows)

    first = draw(flat, drawn)
    again = draw(flat.copy(), drawn)
    assert all(a is b for a, b in zip(first, again, strict=True))
    stepped = flat.copy()
    stepped[-100:] = 9.0  # the last half second steps up: rows 0 to 4 of 8 reached
    third = draw(stepped, drawn)
    remade = [r for r, (a, b) in enumerate(zip(again, third, strict=True)) if a is not b]
    assert remade and remade == list(range(remade[0], remade[-1] + 1)) and len(remade) < 8
    assert third == draw(stepped, None)


def test_a_flat_line_in_the_middle_of_its_plot_stays_on_its_row_through_noise() -> None:
    """An auto-scaled plot centres a joint at rest: its line lies on the middle of the range,
    which is now a row's middle, so noise far below a dot's height leaves the picture as it
    was. It was the edge between two rows: the line flipped between them with the noise's
    sign, and the row was drawn again every frame."""
    x = np.linspace(-10.0, 0.0, 2000)
    style = Style(color="cyan")
    pictures = {tuple(strip.text for strip in render(
        [Trace(x, np.full(2000, 1.5 + noise), style)], (-10.0, 0.0), (1.0, 2.0), 60, 8))
        for noise in (-1e-6, 0.0, 1e-6)}
    assert len(pictures) == 1


def thread_wakeups(thread: threading.Thread) -> int:
    """How many times ``thread`` has gone to sleep and been woken (its voluntary switches)."""
    status = Path(f"/proc/self/task/{thread.native_id}/status").read_text()
    return int(next(line.split()[1] for line in status.splitlines()
                    if line.startswith("voluntary_ctxt_switches")))
