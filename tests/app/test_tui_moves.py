"""Moves tab: a step form runs a move on the simulator and its run appears in Runs; Abort
holds, and a run the recorder could not save is kept in Runs and saved elsewhere; an
invalid field shows its error and runs nothing; the end-point form lists every inverse
solution; the rig initialises and runs its sequence of positions and dwell times; a
path file is played, and a malformed one is reported with its line."""

from __future__ import annotations

import asyncio
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import DataTable, Input, OptionList, ProgressBar, Switch, TextArea

from app.tabs.end_point_form import POSE_FIELDS, EndPointForm
from app.tabs.moves import MovesTab
from app.tabs.runs import RunsTab
from app.widgets.fields import NumberField
from app.widgets.live_text import LiveText
from control.motion.robot_model import builtin_unimate
from control.rt.layout import Mode
from control.run_mcap import read_mcap
from tests.app.test_tui_program import DriverPilot

SIZE = (160, 48)
MODEL = builtin_unimate()  # the built-in Unimate's kinematics


async def choose(app, pilot, label: str) -> None:
    kinds = app.query_one("#move-kinds", OptionList)
    kinds.highlighted = next(i for i in range(kinds.option_count)
                             if str(kinds.get_option_at_index(i).prompt) == label)
    await pilot.pause()


def field(app, form: str, name: str) -> NumberField:
    return app.query_one(f"#form-{form} #{name}", NumberField)


async def run_and_wait(tui, app, pilot) -> MovesTab:
    tab = app.query_one(MovesTab)
    await pilot.press("ctrl+s")
    error = app.query_one("#move-error")
    await tui.until(lambda: tab.handle is not None or tab.last_result is not None, timeout=10,
                    what=lambda: f"the move to start (error: {error.render()!s}; "
                                 f"state: {app.query_one('#move-state').render()!s})")
    await tui.until(lambda: tab.handle is None, timeout=60, what="the move to end")
    await pilot.pause()
    return tab


def test_step_runs_on_the_simulator_and_appears_in_runs(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            start = await tui.ready(app, pilot)
            await pilot.press("f2")
            await choose(app, pilot, "Step")
            target = round(start.position[2] + 5.0, 1)
            app.query_one("#form-step JointField Select").value = 2  # Up/Down
            field(app, "step", "target").text = str(target)
            title = app.query_one("#move-preview-title")
            await tui.until(lambda: "step Up/Down" in title.render().plain,
                            what=lambda: f"the step previewed: {title.render().plain}")
            tab = await run_and_wait(tui, app, pilot)
            result = tab.last_result
            assert result is not None and result.complete, result and result.status
            assert abs(app.client.status().position[2] - target) < 1.0
            rows = app.query_one("#move-result", DataTable)
            assert rows.row_count >= 1 and rows.get_row_at(0)[0] == "Up/Down"
            saved = sorted(data_dir.glob("*-step.json"))
            assert len(saved) == 1 and result.files.json == saved[0]
            await pilot.press("f6")
            runs = app.query_one(RunsTab)
            await tui.until(lambda: runs.infos, what="the run listed")
            assert runs.infos[0].files.stem == saved[0].stem
            runs.open_latest()
            await tui.until(lambda: runs.run is not None, what="the run opened")
            assert runs.run.kind == "step" and runs.run.samples == result.run.samples
            await pilot.press("v")  # plotsix 4-6
            seen = tui.notifications(app)  # an export says so once its file is written
            await pilot.press("x")
            await tui.until(lambda: any(m.startswith("exported") and ".svg" in m for m in seen),
                            what=lambda: f"export: {seen}")
            (svg,) = (data_dir / "plots").glob("*.svg")  # the plot on screen, from its data
            lines = ET.parse(svg).getroot().findall(".//{http://www.w3.org/2000/svg}polyline")
            assert len(lines) == len(runs.figure().panels) // 2 * 3  # desired, actual; duty
            await pilot.press("m")
            await tui.until(lambda: any(m.startswith("exported") and m.endswith(".mcap")
                                        for m in seen), what=lambda: f"MCAP: {seen}")
            (mcap,) = (data_dir / "exports").glob("*.mcap")
            record, topics = read_mcap(mcap)
            assert record["kind"] == "step"
            assert len(topics["/joints/actual"]) == runs.run.samples

    asyncio.run(scenario())


def test_abort_holds_and_an_unsaved_run_is_kept_and_saved_elsewhere(tui, tmp_path: Path
                                                                     ) -> None:
    blocker = tmp_path / "not-a-directory"  # the recorder cannot save under a file
    blocker.write_text("a file where the data directory's parent should be\n")
    tui.data_dir = blocker / "runs"
    elsewhere = tmp_path / "elsewhere"

    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the move is still under way at Abort
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            start = await tui.ready(app, pilot)
            await pilot.press("f2")
            await choose(app, pilot, "Step")
            app.query_one("#form-step JointField Select").value = 1  # Rotate
            field(app, "step", "target").text = f"{start.position[1] + 20.0:.1f}"
            field(app, "step", "duration").text = "20"
            tab = app.query_one(MovesTab)
            await pilot.press("ctrl+s")
            await tui.until(lambda: tab.handle is not None, what="the move to start")
            await tui.until(lambda: app.client.status().move_done > 0, what="the move under way")
            await pilot.click("#move-abort")
            await tui.until(lambda: tab.last_result is not None, timeout=20,
                            what="the aborted move to end")
            result = tab.last_result
            assert result.status == "aborted by operator" and result.files is None, result.status
            assert "Not a directory" in (result.save_error or ""), result.save_error
            # the progress stays where the move stopped, and says so
            bar = app.query_one("#move-progress", ProgressBar)
            assert bar.progress == result.run.samples and 0 < bar.percentage < 1
            state = app.query_one("#move-state", LiveText).text
            assert f"({100 * bar.percentage:.0f} %)" in state, state
            assert app.client.status().mode == Mode.HOLD
            await pilot.press("f6")
            runs = app.query_one(RunsTab)
            await tui.until(lambda: runs.unsaved, what="the unsaved run kept")
            assert runs.unsaved[0] is result.run
            await tui.until(lambda: app.query_one("#runs-table", DataTable).row_count,
                            what="the unsaved run listed")
            runs.open_latest()
            await tui.until(lambda: runs.run is result.run, what="the unsaved run opened")
            app.query_one("#runs-save-dir", Input).value = str(elsewhere)
            save = app.query_one("#runs-save-button")
            await tui.until(lambda: save.region.height, what="the save button laid out")
            await pilot.click(save)
            await tui.until(lambda: list(elsewhere.glob("*-step.json")), what="saved elsewhere")
            await tui.until(lambda: not runs.unsaved, what="no longer listed as unsaved")

    asyncio.run(scenario())


def test_invalid_fields_run_nothing_and_a_late_menu_choice_keeps_the_focus(tui, data_dir: Path
                                                                          ) -> None:
    """Two flows of the Step form on one app, one after the other (they were two tests, each
    with an app of its own; the first moves nothing)."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            await an_invalid_field_shows_its_error_and_runs_nothing(app, pilot, data_dir)
            await a_menu_choice_selected_late_leaves_the_field_the_operator_chose(tui, app, pilot)

    asyncio.run(scenario())


async def an_invalid_field_shows_its_error_and_runs_nothing(app, pilot, data_dir: Path) -> None:
    await pilot.press("f2")
    await choose(app, pilot, "Step")
    target = field(app, "step", "target")
    error = app.query_one("#move-error")
    for text, expected in (("abc", "is not a number"), ("nan", "not a usable number"),
                           ("5000", "outside 976…2041mm")):
        target.text = text
        await pilot.pause()
        shown = str(target.query_one(".field-error").render())
        assert expected in shown, shown
        await pilot.press("ctrl+s")
        assert expected in str(error.render())
    await asyncio.sleep(0.3)
    assert app.query_one(MovesTab).handle is None
    assert app.client.status().mode == Mode.HOLD
    assert not list(data_dir.glob("*.json"))
    await choose(app, pilot, "Sine")
    field(app, "sine", "end").text = "2000"
    field(app, "sine", "period").text = "0.5"  # far too fast for In/Out
    await pilot.press("ctrl+s")
    assert "max_speed" in str(error.render())
    assert not list(data_dir.glob("*.json"))


async def a_menu_choice_selected_late_leaves_the_field_the_operator_chose(tui, app, pilot
                                                                          ) -> None:
    """On a loaded machine a click on the Moves menu is selected late: the operator has
    clicked a field and typed by then. That selection must not take the focus to the form's
    first field (the joint chooser), where the keys typed next were lost: the failure of
    test_typing_tmux under load, seen with a log of every focus change. Chosen from the menu
    with the focus still on it, the first field takes the keys as before."""
    await pilot.press("f2")
    await tui.until(lambda: app.query("#form-step #start"), timeout=30,
                    what="the Moves tab's step form")
    await choose(app, pilot, "Step")  # shown, as a fresh app's first form
    menu = app.query_one("#move-kinds", OptionList)
    start = field(app, "step", "start")
    await pilot.click(start.input)
    await pilot.press("5")
    await tui.until(lambda: start.text.endswith("5"), what="5 in the start field")
    index = menu.highlighted or 0
    menu.post_message(OptionList.OptionSelected(menu, menu.get_option_at_index(index),
                                                index))
    await pilot.pause()
    await pilot.press("0")
    assert app.focused is not None and start in app.focused.ancestors_with_self, \
        app.focused
    assert start.text.endswith("50")
    menu.focus()
    await pilot.pause()
    await pilot.press("enter")
    await tui.until(lambda: app.focused is not menu, what="a field after Enter")
    first = next(w for w in app.query_one(MovesTab).form.query("Input, Select")
                 if w.focusable)
    assert app.focused is first


def test_a_path_file_then_via_points_play(tui, tmp_path: Path) -> None:
    """The path file's flow, then the via points' (joint space, then Cartesian), on one app
    (they were two tests, each with an app of its own; each starts from where the arm is)."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            await path_file_plays_and_a_bad_line_is_reported(tui, app, pilot, tmp_path)
            await via_points_preview_and_run_in_joint_space_and_cartesian(tui, app, pilot)

    asyncio.run(scenario())


async def path_file_plays_and_a_bad_line_is_reported(tui, app, pilot, tmp_path: Path) -> None:
    good = tmp_path / "wave.csv"
    bad = tmp_path / "bad.csv"
    status = app.client.status()
    q = status.position[3]
    good.write_text(f"t,Bend\n0,{q}\n0.5,{q + 5}\n1.0,{q}\n")
    bad.write_text(f"t,Bend\n0,{q}\n0.5,{q}+5\n")
    await pilot.press("f2")
    await choose(app, pilot, "Path file")
    path_input = app.query_one("#path-file")
    path_input.focus()
    path_input.value = str(bad)
    await pilot.press("enter")
    state = app.query_one("#path-state")
    await tui.until(lambda: "line 3" in str(state.render()), what="the bad line")
    path_input.value = str(good)
    await pilot.press("enter")
    await tui.until(lambda: "3 points" in str(state.render()), what="the file loaded")
    tab = await run_and_wait(tui, app, pilot)
    assert tab.last_result.complete, tab.last_result.status
    assert tab.last_result.run.meta["file"] == str(good.resolve())
    # the run just saved plays again from the same form, by its JSON
    first = tab.last_result
    path_input.value = str(first.files.json)
    await pilot.press("enter")
    await tui.until(lambda: f"the path run {first.files.stem}" in str(state.render()),
                    what="the run loaded")
    tab = await run_and_wait(tui, app, pilot)
    again = tab.last_result
    assert again.complete and again.run.meta["replays"].startswith("the path run")
    rows = first.run.meta["path_samples"]
    approach = again.run.meta["approach_samples"]
    np.testing.assert_allclose(again.run.desired[approach:approach + rows],
                               first.run.desired[:rows], atol=1e-6)


async def via_points_preview_and_run_in_joint_space_and_cartesian(tui, app, pilot) -> None:
    status = app.client.status()
    q = np.array(status.position)
    await pilot.press("f2")
    await choose(app, pilot, "Via points")
    area = app.query_one("#via-points", TextArea)
    area.text = "1500 0 0 0 0 0 0"
    await pilot.press("ctrl+s")
    assert "line 1: 7 numbers" in str(app.query_one("#move-error").render())
    via = q + np.array([40.0, 5.0, 2.0, 5.0, 0.0, 0.0])
    back = q + np.array([0.0, 10.0, 0.0, 0.0, 0.0, 0.0])
    area.text = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in (via, back))
    title = app.query_one("#move-preview-title")
    await tui.until(lambda: "path through 2 via points" in title.render().plain,
                    what=lambda: f"the path previewed: {title.render().plain}")
    tab = await run_and_wait(tui, app, pilot)
    result = tab.last_result
    assert result.complete and result.run.kind == "via_points", result.status
    assert np.allclose(result.run.meta["points"][0], np.round(via, 3))
    final = np.array(app.client.status().position)
    assert abs(final[1] - (q[1] + 10.0)) < 1.0, final
    app.query_one("#via-cartesian", Switch).value = True
    start = MODEL.pose(final)[:3]
    area.text = (f"{start[0] + 40:.2f} {start[1]:.2f} {start[2]:.2f}\n"
                 f"{start[0] + 40:.2f} {start[1] + 60:.2f} {start[2] + 20:.2f}")
    await tui.until(lambda: "Cartesian path through 2 points" in title.render().plain,
                    what=lambda: f"the Cartesian path previewed: {title.render().plain}")
    tab = await run_and_wait(tui, app, pilot)
    assert tab.last_result.complete and tab.last_result.run.kind == "cartesian"
    desired = tab.last_result.run.desired
    assert np.allclose(MODEL.pose(desired[-1])[:3], start + np.array([40, 60, 20]),
                       atol=0.01)
    assert np.ptp(desired[:, 4:], axis=0).max() < 1e-6  # γ β held: Yaw, Swivel still
    assert np.allclose(app.client.status().position, desired[-1], atol=1.0)


def test_end_point_lists_every_solution_and_runs_the_one_picked(tui) -> None:
    # two in-limit branches: the wrist flipped (Yaw −62° or +62°, Swivel + 180°)
    two_ways = np.array([1521.1, 99.1, -18.8, 98.7, -62.0, -27.6])

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            status = await tui.ready(app, pilot)
            await pilot.press("f2")
            await choose(app, pilot, "End point")
            form = app.query_one(EndPointForm)
            table = app.query_one("#ik-solutions", DataTable)
            form.solve(np.array(status.position))  # the current pose, filled in
            nearest = np.array([float(v) for v in table.get_row_at(0)[1:]])
            assert np.allclose(nearest, status.position, atol=0.5)  # 3 decimals, Yaw near 0
            for (_, _, key), value in zip(POSE_FIELDS, MODEL.pose(two_ways), strict=True):
                app.query_one(f"#form-end_point #pose-{key}", NumberField).text = f"{value:.4f}"
            form.solve(np.array(status.position))
            assert table.row_count == 2
            solutions = [np.array([float(v) for v in table.get_row_at(k)[1:]]) for k in (0, 1)]
            assert any(np.allclose(q, two_ways, atol=0.05) for q in solutions)
            table.move_cursor(row=1)
            tab = await run_and_wait(tui, app, pilot)
            assert tab.last_result.complete, tab.last_result.status
            assert tab.last_result.run.meta["solution_index"] == 1
            final = np.array(app.client.status().position)
            assert np.allclose(final, solutions[1], atol=2.0), final
            app.query_one("#form-end_point #pose-x", NumberField).text = "9000"
            form.solve(final)
            assert "unreachable" in str(app.query_one("#ik-state").render())
            assert table.row_count == 0
            await pilot.press("ctrl+s")
            assert "unreachable" in str(app.query_one("#move-error").render())

    asyncio.run(scenario())


def test_rig_initialises_then_runs_its_sequence(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            assert not app.client.status().homed
            await pilot.press("f2")
            await choose(app, pilot, "Initialise")
            await pilot.press("ctrl+s")
            await tui.until(lambda: app.client.status().homed, timeout=30, what="homed")
            await choose(app, pilot, "Multi-step")
            field(app, "multi_step", "count").text = "2"
            for i, (position, dwell) in enumerate(((150, 1.0), (60, 1.0))):
                field(app, "multi_step", f"pos{i}").text = str(position)
                field(app, "multi_step", f"dwell{i}").text = str(dwell)
            tab = await run_and_wait(tui, app, pilot)
            assert tab.last_result is not None and tab.last_result.complete
            rows = app.query_one("#move-result", DataTable)
            assert [rows.get_row_at(i)[0] for i in range(rows.row_count)] == [
                "Ram step 1", "Ram step 2"]
            assert abs(app.client.status().position[0] - 60) < 2.0
            await choose(app, pilot, "Set pulse")
            tab = await run_and_wait(tui, app, pilot)
            assert tab.last_result.complete and tab.last_result.run.kind == "set_pulse"

    asyncio.run(scenario())


def test_after_a_jog_the_forms_show_the_new_pose_and_run_from_it(tui) -> None:
    """The issue's sequence: End point seen, Rotate jogged elsewhere, End point again shows
    the pose where the arm is now, and ctrl+s there does not drive the arm back."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            before = await tui.ready(app, pilot)
            client = app.client
            await pilot.press("f2")
            await choose(app, pilot, "End point")  # filled with the pose before the jog
            x = app.query_one("#form-end_point #pose-x", NumberField)
            now = MODEL.pose(np.array(client.status().position))
            assert float(x.text) == pytest.approx(now[0], abs=1.0)  # the arm still settles
            await pilot.press("f1", "9", "s", "s")  # Rotate at 18 % duty
            await tui.until(lambda: client.status().position[1] > before.position[1] + 5.0,
                            timeout=30, what="Rotate jogged 5° on")
            await pilot.press("space", "enter")
            await tui.until(lambda: client.status().mode == Mode.HOLD, what="holding again")
            await tui.until(lambda: abs(client.status().desired[1] - client.status().position[1])
                            < 0.05, timeout=30, what="Rotate settled where it holds")
            ahead = MODEL.pose(np.array(client.status().position))
            await pilot.press("f2")
            await pilot.pause()
            jogged = np.array(client.status().position)
            pose = MODEL.pose(jogged)
            assert abs(pose[0] - now[0]) > 10.0  # x moved with Rotate: a stale x would show
            for (_, unit, key), value, moved in zip(POSE_FIELDS, pose, np.abs(pose - ahead),
                                                    strict=True):
                shown = float(app.query_one(f"#form-end_point #pose-{key}", NumberField).text)
                # filled between the two looks, the arm still creeping on its hold (2 mm at
                # 1.7 m is 0.07° of Rotate) and the wrist hunting in its band
                near = moved + (2.0 if unit == "mm" else 0.3)
                assert shown == pytest.approx(value, abs=near), key
            tab = await run_and_wait(tui, app, pilot)
            assert tab.last_result.complete, tab.last_result.status
            final = np.array(client.status().position)
            assert abs(final[1] - jogged[1]) < 0.5, (final, jogged)  # stayed where jogged
            assert abs(final[1] - before.position[1]) > 4.5
            await choose(app, pilot, "Step")
            app.query_one("#form-step JointField Select").value = 1  # Rotate
            await pilot.pause()
            start = field(app, "step", "start")
            assert not start.text  # a blank start is where the joint is when the move runs
            here, value = start.input.placeholder.split()  # "here 5.23": Rotate, live
            assert here == "here" and float(value) == pytest.approx(final[1], abs=0.3)
            # the preview says where the move starts: here, or after an approach from here
            field(app, "step", "target").text = f"{final[1] + 5:.1f}"
            title = app.query_one("#move-preview-title")
            await tui.until(lambda: "start here: Rotate" in title.render().plain,
                            what=lambda: f"the start in the preview: {title.render().plain}")
            elsewhere = round(final[1] - 5.0, 1)
            start.text = str(elsewhere)
            await tui.until(lambda: "s first:" in title.render().plain,
                            what=lambda: f"the approach in the preview: {title.render().plain}")
            assert f"→{elsewhere:.2f}°" in title.render().plain

    asyncio.run(scenario())


def test_a_field_chosen_while_the_tabs_build_keeps_the_focus(tui, monkeypatch) -> None:
    """Moves chosen at once after start, on a machine slow to build the tab behind it (the
    Positions tab's code, which the Moves forms wait for, held back here): the Moves tab is
    painted, the operator clicks into a field and types, and the build finishing does not
    take the focus back to the menu, where the keys typed next were lost (the intermittent
    failure of test_typing_tmux). Before, the build held the screen's messages, so nothing
    was painted until every tab was built, and a focus for the tab shown, queued behind the
    build, came after the operator's click."""
    import threading

    from app import tui as tui_module

    held = threading.Event()
    positions = dict(tui_module.TABS)["positions"]

    class HeldBack(tui_module.TabKind):
        def load(self):  # the import finishes when the test lets it
            held.wait(60)
            return positions.load()

    monkeypatch.setattr(tui_module, "TABS", tuple(
        (name, HeldBack(kind.title, kind.module, kind.name) if name == "positions" else kind)
        for name, kind in tui_module.TABS))

    async def scenario() -> None:
        app = tui.app(build_behind=True)  # the operator's, whose build this holds back
        try:
            async with app.run_test(size=SIZE) as pilot:
                pilot = DriverPilot(app)
                tui.post_key(app, "f2")
                await tui.until(lambda: app.query("#form-step #start")
                                and field(app, "step", "start").region.area > 0,
                                timeout=30, what="the Moves tab's step form painted")
                start = field(app, "step", "start")
                await pilot.click(start.input)
                await pilot.press("5")
                await tui.until(lambda: start.text.endswith("5"),
                                what=lambda: f"5 in the start field (the focus: {app.focused!r})")
                assert app.tabs.made_tab("positions") is None, "the build was not held back"
                held.set()
                await tui.until(lambda: app.tab("positions").is_mounted and not app._building
                                and app._active is app.tab("moves"), timeout=30,
                                what="the Positions tab built and Moves shown")
                await pilot.pause()
                await pilot.press("0")
                assert app.focused is not None and start in app.focused.ancestors_with_self
                assert start.text.endswith("50")
                app._focus_active()  # a late focus for the tab shown, as a build's can come
                await pilot.press("1")
                assert start.text.endswith("501"), f"the focus went to {app.focused!r}"
        finally:
            held.set()

    asyncio.run(scenario())
