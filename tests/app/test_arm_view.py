"""The arm's view in the TUI (issue 28): on the Jog tab (p) and on its own screen (^A, with the
Moves tab's previewed path), at 80×24 and 160×48, on the real controller; a near-limit joint
coloured; an idle view draws nothing; the ghost and the previewed path shown. The full view in
the browser (``servodesk serve``) is checked in tests/app/test_serve.py, on the commanding
session's page, whose serve, controller and Chromium it shares."""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Callable

import numpy as np
from textual.app import App, ComposeResult
from textual.widgets import OptionList, TextArea

from app.plotting.arm_scene import GHOST, JOINT_LEVELS, JOINT_PATH, LINK
from app.screens.arm import ArmScreen
from app.widgets.arm_view import ArmView
from control.motion.positions import PositionBook, positions_file, save_positions
from control.motion.robot_model import builtin_unimate
from control.rt.layout import Flag, Mode, Status
from hw.machine import load_machine
from tests.app.conftest import Tui

MACHINE = load_machine("unimate2000b")
SMALL, LARGE = (80, 24), (160, 48)
BRAILLE = range(0x2801, 0x2900)


def status(position: tuple[float, ...], desired: tuple[float, ...] | None = None) -> Status:
    """A status record as the controller publishes it, at ``position`` (``desired`` NaN in
    manual actuation, where nothing is targeted)."""
    zeros = (0.0,) * 6
    return Status(tick=1, time_s=0.0, wall_ns=0, mode=Mode.HOLD, flags=Flag(0), move_id=0,
                  move_done=0, move_total=0, late_last_us=0.0, late_max_us=0.0, overruns=0,
                  compute_last_us=0.0, compute_max_us=0.0, compute_total_s=0.0,
                  io_total_s=0.0, feed_override=1.0, feed_rate=1.0, supply_mpa=float("nan"),
                  position=position, desired=desired or position, duty=zeros, valve=zeros,
                  settle_s=zeros, raw=(0,) * 6, glitches=(0,) * 6, link={}, fault="")


class ViewApp(App[None]):
    """The view alone, fed by ``source``."""

    def __init__(self, source: Callable[[], Status | None]) -> None:
        super().__init__()
        self.source = source

    def compose(self) -> ComposeResult:
        yield ArmView(MACHINE, builtin_unimate(), self.source)


def fresh(record: Status) -> Status:
    """The same status as a new record, every number a new object, as each one read from
    shared memory is (a NaN is then not the NaN of the last one)."""
    return dataclasses.replace(record, position=tuple(np.array(record.position).tolist()),
                               desired=tuple(np.array(record.desired).tolist()))


def drawn(view: ArmView) -> str:
    return Tui.text(view)


def has_braille(view: ArmView) -> bool:
    return sum(ord(c) in BRAILLE for c in drawn(view)) > 20


def cells_styled(view: ArmView, style: object) -> int:
    """How many cells of the view are drawn in ``style``."""
    return sum(len(seg.text.replace(" ", "")) for y in range(view.size.height)
               for seg in view.render_line(y) if seg.style == style)


def test_an_idle_view_draws_once_and_a_new_pose_draws_again() -> None:
    home = tuple(MACHINE.home)
    now = {"status": status(home)}

    async def scenario() -> None:
        app = ViewApp(lambda: fresh(now["status"]))
        async with app.run_test(size=LARGE) as pilot:
            view = app.query_one(ArmView)
            await Tui.until(lambda: view.draws >= 1, what="the first frame")
            polls = view.polls
            await Tui.until(lambda: view.polls >= polls + 10, what="ten polls")
            assert view.draws == 1, "the same pose was drawn again"
            moved = (home[0] + 100.0, *home[1:])
            now["status"] = status(moved, desired=home)
            await Tui.until(lambda: view.draws == 2, what="the new pose drawn")
            await pilot.pause()
            assert cells_styled(view, GHOST) > 0, "no ghost of the desired pose"
            now["status"] = status(moved, desired=(float("nan"),) * 6)  # manual: no target
            await Tui.until(lambda: view.draws == 3, what="the pose without a target drawn")
            polls = view.polls
            await Tui.until(lambda: view.polls >= polls + 10, what="ten polls")
            assert view.draws == 3, "no target (NaN) is no change: nothing to draw again"
            assert cells_styled(view, GHOST) == 0 and cells_styled(view, LINK) > 0
            await pilot.press("f")  # the keys need the focus: the view is the only focusable
            await Tui.until(lambda: view.view.name == "front" and view.draws == 4,
                            what="the front view drawn")

    asyncio.run(scenario())


async def _full_view_shows(tui: Tui, app, pilot, size: tuple[int, int]) -> None:
    """^A: the arm on the whole screen at ``size``, the near-limit joint coloured; q: back."""
    await pilot.press("ctrl+a")
    await tui.until(lambda: isinstance(app.screen, ArmScreen))
    full = app.screen.query_one(ArmView)
    await tui.until(lambda: has_braille(full) and full.size.width == size[0],
                    what=lambda: drawn(full))
    assert cells_styled(full, JOINT_LEVELS[2]) > 0, f"no near-limit joint at {size}"
    await pilot.press("q")
    await tui.until(lambda: not isinstance(app.screen, ArmScreen))


def test_the_jog_tab_and_the_full_screen_show_the_arm_and_the_moves_preview(tui) -> None:
    """One app at 80×24, its terminal then made 160×48 (as an operator's is resized): at each
    size the Jog tab's view (p) draws the arm with a joint near its limit coloured and named,
    and ^A's full screen does too; then, at 160×48, the Moves tab's previewed path on ^A's
    full screen. (Three apps, one started at each size and one for the preview, checked the
    same things with two controllers, two apps and a go-to more.)"""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SMALL) as pilot:
            start = await tui.ready(app, pilot)
            assert not app.query("#jog-arm"), "the Jog tab makes its view only when first shown"
            await pilot.press("p")
            view = app.query_one("#jog-arm", ArmView)
            await tui.until(lambda: has_braille(view), what=lambda: drawn(view))
            assert view.size.height >= 9
            assert "isometric" in drawn(view).splitlines()[0]
            near = list(start.position)
            near[2] = MACHINE.joints[2].upper - 0.5  # Up/Down within 2 % of its limit
            await asyncio.to_thread(app.client.wait, app.client.go_to(near, speed=1.0), 30)
            await tui.until(lambda: cells_styled(view, JOINT_LEVELS[2]) > 0,
                            what=lambda: drawn(view))
            assert "Up/Down near its limit" in drawn(view).splitlines()[0]
            await _full_view_shows(tui, app, pilot, SMALL)

            draws = view.draws
            await pilot.resize_terminal(*LARGE)
            await tui.until(lambda: app.screen.size == LARGE and view.draws > draws
                            and view.size.width > SMALL[0] and has_braille(view),
                            what=lambda: f"the view drawn at {LARGE}: {drawn(view)}")
            assert view.size.height >= 25
            assert "isometric" in drawn(view).splitlines()[0]
            assert "Up/Down near its limit" in drawn(view).splitlines()[0]
            assert cells_styled(view, JOINT_LEVELS[2]) > 0
            await _full_view_shows(tui, app, pilot, LARGE)

            await pilot.press("p")  # and back: the table and the help again
            await tui.until(lambda: not view.display and app.query_one("#jog-help").display)
            file = positions_file(app.data_dir, MACHINE)  # a position taught meanwhile
            save_positions(PositionBook(MACHINE).teach("spot", near), file)
            await pilot.press("p")  # shown again: marked
            await tui.until(lambda: "spot" in [m.name for m in view.plan.markers],
                            what=lambda: f"spot marked: {view.plan.markers}")
            await _moves_preview_on_the_full_screen(tui, app, pilot, near)

    asyncio.run(scenario())


async def _moves_preview_on_the_full_screen(tui: Tui, app, pilot, here: list[float]) -> None:
    """The Moves tab's previewed path on ^A's full screen, ^A pressed in its via-points field
    (the app's key, not the field's), ^A back, and a tab's key leaving the full view."""
    await pilot.press("f2")
    moves = app.tab("moves")
    await tui.until(lambda: moves.visible_now)
    target = np.array(here)
    target[0] += 500.0  # the tool sweeps a wide arc
    target[1] += 90.0
    kinds = app.query_one("#move-kinds", OptionList)
    kinds.highlighted = next(i for i in range(kinds.option_count)
                             if str(kinds.get_option_at_index(i).prompt) == "Via points")
    await tui.until(lambda: moves.form.KIND == "via_points")
    area = app.query_one("#via-points", TextArea)
    area.focus()
    area.text = " ".join(f"{v:.3f}" for v in target)
    await tui.until(lambda: moves.previewed is not None, what="the preview")
    await pilot.press("ctrl+a")  # typed in the field: the app's, not the field's
    await tui.until(lambda: isinstance(app.screen, ArmScreen))
    full = app.screen.query_one(ArmView)
    await tui.until(lambda: cells_styled(full, JOINT_PATH) > 20, what=lambda: drawn(full))
    await pilot.press("ctrl+a")  # and back
    await tui.until(lambda: not isinstance(app.screen, ArmScreen))
    await pilot.press("ctrl+a", "f1")  # a tab's key leaves the full view for the tab
    await tui.until(lambda: not isinstance(app.screen, ArmScreen)
                    and app.tab("jog").visible_now)


def test_the_rig_view_shows_the_ram_its_limits_and_the_supply(tui) -> None:
    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=SMALL) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("ctrl+a")
            await tui.until(lambda: isinstance(app.screen, ArmScreen))
            full = app.screen.query_one(ArmView)
            await tui.until(lambda: "supply" in drawn(full) and "MPa" in drawn(full),
                            what=lambda: drawn(full))
            text = drawn(full)
            assert "limit 0 mm" in text and "limit 1200 mm" in text and "target" in text

    asyncio.run(scenario())
