"""The Positions tab against the simulator: teach (its key and ^T from any tab), list with
joints and pose, rename, delete, go to (the robot gets there), the E-stop refusal, a damaged
file reported and left alone; the via-point editor takes a taught position."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
from textual.widgets import Button, DataTable, Input, Select, TextArea

from app.tabs.path_forms import ViaPointsForm
from app.tabs.positions import PositionsTab
from app.widgets.dialogs import ConfirmScreen, EditValueScreen
from app.widgets.live_text import LiveText
from control.motion.positions import load_positions, positions_file
from control.motion.robot_model import builtin_unimate
from control.recorder import list_runs, load_run
from control.rt.layout import Mode

SIZE = (160, 48)
MOVE_S = 60.0  # a go-to of a few seconds on a loaded machine


async def name_it(app, pilot, name: str) -> None:
    """Type ``name`` into the open name dialog and press Enter."""
    assert isinstance(app.screen, EditValueScreen), app.screen
    app.screen.query_one(Input).value = name
    await pilot.press("enter")
    assert not isinstance(app.screen, EditValueScreen), "the name was refused"


def test_teach_list_rename_go_to_and_delete(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app()
        path = positions_file(data_dir, app.machine)
        tolerance = np.array([j.goal_tolerance for j in app.machine.joints])  # "at": in position
        async with app.run_test(size=SIZE) as pilot:
            start = np.array((await tui.ready(app, pilot)).position)
            await pilot.press("f2")  # Moves built: its via-point editor is offered what is taught
            await pilot.press("f9")
            tab = app.query_one(PositionsTab)
            table = app.query_one("#positions-table", DataTable)
            await tui.until(lambda: tab.visible_now and table.row_count == 2,
                            what="home and park listed")
            assert [str(k.value) for k in table.rows] == ["home", "park"]

            # teach where the joints are: the file holds it, the table shows joints and pose
            await pilot.press("t")
            await name_it(app, pilot, "station")
            await tui.until(lambda: table.row_count == 3, what="the taught position listed")
            (taught,) = load_positions(path, app.machine).taught
            assert taught.name == "station"
            assert np.all(np.abs(np.array(taught.joints) - start) <= tolerance)  # held there
            row = [str(c) for c in table.get_row("station")]
            x, y, z = builtin_unimate().pose(np.array(taught.joints))[:3]
            assert row[:2] == ["station", "taught"]
            assert row[2:8] == [f"{v:.2f}" for v in taught.joints]
            assert row[8:11] == [f"{x:.1f}", f"{y:.1f}", f"{z:.1f}"]

            # the via-point editor has it to add
            via = app.query_one(ViaPointsForm)
            await tui.until(lambda: [p.name for p in via.named] == ["home", "park", "station"],
                            what="the via-point form offered the positions")
            via.query_one("#via-named", Select).value = 2
            via.query_one("#via-add-named", Button).press()
            area = via.query_one("#via-points", TextArea)
            await tui.until(lambda: area.text.strip(), what="a via point added")
            assert [float(v) for v in area.text.split()] == list(taught.joints)

            # rename: the file and the list follow; a taken name is refused in the dialog
            table.move_cursor(row=2)
            await pilot.press("r")
            app.screen.query_one(Input).value = "park"
            await pilot.press("enter")
            assert isinstance(app.screen, EditValueScreen)  # refused, says why
            assert "machine file's park" in str(app.screen.query_one("#edit-error").render())
            await name_it(app, pilot, "bench")
            await tui.until(lambda: [p.name for p in load_positions(path, app.machine).taught]
                            == ["bench"], what="the file renamed")
            await tui.until(lambda: "bench" in [str(k.value) for k in table.rows])

            # go home (machine file), then back to the taught one: the robot gets there
            state = app.query_one("#positions-state", LiveText)
            app.query_one("#positions-speed Input", Input).value = "0.9"

            async def go_to(row: int, name: str, target: np.ndarray) -> None:
                table.move_cursor(row=row)
                await pilot.press("g")  # it asks first (test_positions_go.py)
                await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
                await pilot.press("y")
                await tui.until(lambda: state.text.startswith(f"at {name}"), MOVE_S,
                                what=lambda: f"arrival at {name}: {state.text}")
                here = np.array(app.client.status().position)
                assert np.all(np.abs(here - target) <= tolerance), (name, here - target)

            await go_to(0, "home", np.array(app.machine.home))
            await go_to(2, "bench", np.array(taught.joints))
            runs = [load_run(info.files.json) for info in list_runs(data_dir)]
            assert sorted((r.meta["position"], r.meta["speed_fraction"]) for r in runs
                          if r.kind == "go_to") == [("bench", 0.9), ("home", 0.9)]  # saved

            # E-stop latched: go to is refused with the reason, nothing moves
            await pilot.press("ctrl+e")
            await tui.until(lambda: app.client.status().estop, what="the E-stop latched")
            table.move_cursor(row=0)
            await pilot.press("g")
            assert "the E-stop is latched: release it (^R)" in state.text
            assert tab.handle is None and app.client.status().mode != Mode.FOLLOW_TRACK

            # delete, after a confirmation
            table.move_cursor(row=2)
            await pilot.press("delete")
            assert isinstance(app.screen, ConfirmScreen)
            await pilot.press("y")
            await tui.until(lambda: not load_positions(path, app.machine).taught,
                            what="the file without it")
            await tui.until(lambda: table.row_count == 2)

            # ^T teaches from another tab
            await pilot.press("f1")
            await pilot.press("ctrl+t")
            await name_it(app, pilot, "from jog")
            await tui.until(lambda: [p.name for p in load_positions(path, app.machine).taught]
                            == ["from jog"], what="taught from the Jog tab")

    asyncio.run(scenario())


def test_a_damaged_file_is_reported_with_its_line_and_left_alone(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app("rig")
        path = positions_file(data_dir, app.machine)
        path.parent.mkdir(parents=True)
        damaged = 'machine = "rig"\n\n[[position]]\nname = "top"\njoints = [1300.0]\n'
        path.write_text(damaged)
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("f9")
            state = app.query_one("#positions-state", LiveText)
            await tui.until(lambda: "line 5" in state.text, what="the damage reported")
            assert "position 1: 'top': Ram at 1300mm is outside its limits 0…1200mm" in state.text
            assert "fix the file" in state.text
            await pilot.press("t")
            await name_it(app, pilot, "bottom")
            await tui.until(lambda: "Nothing was changed" in state.text)
            assert path.read_text() == damaged  # never overwritten
            path.write_text(damaged.replace("1300.0", "1100.0"))
            await pilot.press("l")
            table = app.query_one("#positions-table", DataTable)
            await tui.until(lambda: table.row_count == 3, what="the mended file read again")
            assert [str(c) for c in table.get_row("top")] == ["top", "taught", "1100.00"]  # no pose

    asyncio.run(scenario())
