"""Positions "go" asks first (issue 26 item 7): the dialog names the largest joint travel,
the tool's distance and the planned time of the path that will run; cancelled, nothing
moves; confirmed, that path runs and leaves its result rows and its run; refused with the
reason, and no dialog, while a go-to runs or the E-stop is latched."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
from textual.widgets import DataTable, Input

from app.tabs.positions import PositionsTab
from app.widgets.dialogs import ConfirmScreen
from app.widgets.live_text import LiveText
from control.motion.robot_model import builtin_unimate
from control.recorder import list_runs, load_run
from control.rt.layout import Mode

SIZE = (160, 48)
MOVE_S = 60.0  # a go-to of a few seconds on a loaded machine


def test_go_asks_first_and_leaves_its_result(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            start = np.array((await tui.ready(app, pilot)).position)
            await pilot.press("f9")
            tab = app.query_one(PositionsTab)
            table = app.query_one("#positions-table", DataTable)
            state = app.query_one("#positions-state", LiveText)
            await tui.until(lambda: tab.visible_now and table.row_count == 2,
                            what="home and park listed")
            app.query_one("#positions-speed Input", Input).value = "1"
            table.move_cursor(row=0)  # home, from park where the arm starts
            home = np.array(app.machine.home)

            # g asks: the travel, the tool's distance and the time, nothing sent
            await pilot.press("g")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
            detail = str(app.screen.query_one(".dialog-detail").render())
            travel = np.abs(home - start)
            model = builtin_unimate()
            distance = np.linalg.norm(model.pose(home)[:3] - model.pose(start)[:3])
            assert f"In/Out {travel[0]:.1f} mm" in detail, detail
            assert f"The tool ends {distance:.0f} mm (straight line)" in detail, detail
            assert " s at 1 of full speed" in detail, detail
            assert app.client.status().mode != Mode.FOLLOW_TRACK

            # n cancels: nothing moves, no run
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, ConfirmScreen))
            assert "cancelled" in state.text, state.text
            assert tab.handle is None and app.client.status().mode != Mode.FOLLOW_TRACK
            assert not list_runs(data_dir)

            # Enter confirms: the planned path runs (held at its start by a 0 % feed
            # override, so that g meanwhile is refused at once), then goes on
            app.client.feed_override(0.0)
            await pilot.press("g")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
            await pilot.press("enter")
            await tui.until(lambda: tab.handle is not None, what="the go-to sent")
            await pilot.press("g")
            assert not isinstance(app.screen, ConfirmScreen)
            assert "a go-to is running" in state.text, state.text
            app.client.feed_override(1.0)
            await tui.until(lambda: state.text.startswith("at home"), MOVE_S,
                            what=lambda: f"arrival at home: {state.text}")
            result = app.query_one("#positions-result", DataTable)
            assert result.display and result.row_count, "no result rows"
            rows = {str(result.get_row_at(i)[0]) for i in range(result.row_count)}
            assert "In/Out" in rows, rows
            runs = [load_run(info.files.json) for info in list_runs(data_dir)]
            assert [(r.kind, r.meta["position"]) for r in runs] == [("go_to", "home")]

            # E-stop latched: refused with the reason, before any dialog
            await pilot.press("ctrl+e")
            await tui.until(lambda: app.client.status().estop, what="the E-stop latched")
            table.move_cursor(row=1)
            await pilot.press("g")
            assert not isinstance(app.screen, ConfirmScreen)
            assert "the E-stop is latched: release it (^R)" in state.text, state.text

    asyncio.run(scenario())
