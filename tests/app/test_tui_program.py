"""The Program tab (issue 27 item 2) on the real controller, lockstep: a program taught from
Positions (steps inserted, moved, deleted), saved, opened again and checked, single-stepped
and run to the end, its moves listed together on the Runs tab; a bad program shows each
problem's line and step and cannot run; feed hold and resume, stop, a start from a step that
asks first, an operator's wait, the refusals (a move running elsewhere, the E-stop latched,
the rig not zeroed, an observer); in reduced speed (T1) the program advances only while the
enabling key repeats, and a release is a feed hold; the rig's example program runs from the
tab. The edits and the Runs tab's grouping are checked without a controller too."""

from __future__ import annotations

import asyncio
import time
import unicodedata
from pathlib import Path

import numpy as np
import pytest
from textual import events
from textual.app import App
from textual.dom import DOMNode
from textual.keys import REPLACED_KEYS, _character_to_key, _get_unicode_name_from_key
from textual.widgets import DataTable, Input

from app.run_groups import grouped, program_cell
from app.tabs.program import ProgramTab
from app.tabs.program_edit import delete_step, insert_go_to, move_step
from app.widgets.dialogs import ConfirmScreen, EditValueScreen
from control.motion import form_plans
from control.program import RunnerState, parse_program, read_program
from control.program.model import GoTo
from control.recorder import RunFiles, RunInfo
from tests.app.conftest import PilotedApp, TabPilot, Tui

SIZE = (120, 36)
RUN_S = 60.0  # a program of a few go-tos on a loaded two-core machine
EXAMPLES = Path(__file__).resolve().parents[2] / "programs"
REPEAT_S = 0.03  # a terminal's auto-repeat


class DriverPilot(TabPilot):
    """Keys as the terminal's driver delivers them, each taken before the next: by the app,
    the widget with the focus and each container a key it leaves bubbles through (a callback
    sent after the key, then one on each of them in turn), the tab it chose built, every
    widget of the screen, and, if another tab or screen is shown, the screen refreshed (the
    tab is focused then) and the focus given. Pilot's press waited besides for an idle
    process twice a key (20 ms to a second each: the app's sampler and client threads keep
    it busy), which said nothing a test reads: what a key does is waited for by a condition."""

    async def press(self, *keys: str) -> None:
        for key in keys:
            shown = (self.app._active, self.app.screen)
            self.app._driver.send_message(key_event(key))
            await taken(self.app)
            await Tui.built(self.app, self)
            if (self.app._active, self.app.screen) != shown:  # focused after a refresh
                await refreshed(self.app)
                await self._wait_for_screen()  # that focus is a callback of the app's


def key_event(key: str) -> events.Key:
    """The event a terminal's key gives (as Pilot's press makes it)."""
    if len(key) == 1 and not key.isalnum():
        key = _character_to_key(key)
    try:
        char = unicodedata.lookup(_get_unicode_name_from_key(REPLACED_KEYS.get(key, key)))
    except KeyError:
        char = key if len(key) == 1 else None
    return events.Key(key, char)


async def taken(app: App) -> None:
    """Until the keys sent so far have been taken by the app, the focused widget and each of
    its containers up to the app."""
    done: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def then(pumps: list[DOMNode]) -> None:
        while pumps and not pumps[0].call_later(then, pumps[1:]):
            pumps = pumps[1:]  # closed meanwhile
        if not pumps and not done.done():
            done.set_result(None)

    def start() -> None:
        then([app.focused, *app.focused.ancestors] if app.focused else [])

    app._driver.send_message(events.Callback(callback=start))
    await asyncio.wait_for(done, 30)


async def refreshed(app: App) -> None:
    """Until the callbacks asked for after the screen's next refresh have run."""
    done: asyncio.Future[None] = asyncio.get_running_loop().create_future()
    app.call_after_refresh(lambda: done.done() or done.set_result(None))
    await asyncio.wait_for(done, 30)


async def program_tab(tui, app, pilot) -> ProgramTab:
    await pilot.press("f11")
    tab = app.query_one(ProgramTab)
    await tui.until(lambda: tab.visible_now, what="the Program tab shown")
    return tab


async def open_path(tui, tab: ProgramTab, pilot, path: Path) -> None:
    """Type ``path`` in the path field, Enter: read (then checked), or a new program offered."""
    field = tab.query_one("#program-path", Input)
    field.value = str(path)
    field.focus()
    before = tab.program
    await pilot.press("enter")
    await tui.until(lambda: tab.program is not before or isinstance(tab.app.screen,
                                                                    ConfirmScreen),
                    what=f"{path} opened")


async def checked(tui, tab: ProgramTab) -> None:
    await tui.until(lambda: not tab.checking and (tab.checked is not None or tab.problems),
                    what="the check")


async def listed(tui, tab: ProgramTab, pilot) -> list[str]:
    """The steps' table as shown (once its columns have taken their new widths)."""
    await pilot.pause()
    return tui.text(tab.query_one("#program-table", DataTable)).splitlines()


def said(tui, tab: ProgramTab) -> str:
    return tab.query_one("#program-state").text


async def ended(tui, tab: ProgramTab) -> None:
    await tui.until(lambda: tab.runner is not None and tab.runner.state.over, RUN_S,
                    what=lambda: f"the program's end ({said(tui, tab)})")


BAD = """name = "bad"
machine = "unimate2000b"

[[step]]
go = "nowhere"

[[step]]
move = "step"
joint = "Up/Down"
target = 40.0
"""

SLOW = """name = "slow"
machine = "unimate2000b"

[[step]]
go = "park"
speed = 0.1

[[step]]
go = "home"
speed = 1.0
"""

T1 = """name = "t1"
machine = "unimate2000b"

[[step]]
move = "step"
joint = "Up/Down"
target = 5.0
duration = 6.0

[[step]]
go = "home"
speed = 1.0
"""


def test_a_program_is_taught_saved_opened_stepped_and_run(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app()
        path = data_dir / "programs" / "taught.toml"
        path.parent.mkdir(parents=True)
        (path.parent / "bad.toml").write_text(BAD)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            start = np.array((await tui.ready(app, pilot)).position)
            tab = await program_tab(tui, app, pilot)
            await open_path(tui, tab, pilot, path)  # no such file: a new program, after asking
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            await pilot.press("y")
            await tui.until(lambda: tab.program is not None and "no steps yet" in
                            tab.query_one("#program-problems").text, what="an empty program")

            # taught: a position taught here, then go tos inserted from the Positions tab
            await pilot.press("f9")
            positions = app.tab("positions")
            table = positions.query_one("#positions-table", DataTable)
            await tui.until(lambda: positions.visible_now and table.row_count == 2)
            await pilot.press("t")
            await tui.until(lambda: isinstance(app.screen, EditValueScreen), what="the name asked")
            app.screen.query_one(Input).value = "spot"
            await pilot.press("enter")
            await tui.until(lambda: table.row_count == 3, what="spot taught")
            positions.query_one("#positions-speed Input", Input).value = "1"

            async def insert(row: int) -> None:
                await pilot.press("f9")
                await tui.until(lambda: positions.visible_now)
                table.move_cursor(row=row)
                await pilot.press("f11")
                await tui.until(lambda: tab.visible_now)
                count = tab.program.count
                await pilot.press("i")
                await tui.until(lambda: tab.program.count == count + 1, what="a step inserted")

            await insert(1)  # park
            await insert(2)  # spot
            await insert(0)  # home, after spot
            assert [s.position for s in tab.program.steps] == ["park", "spot", "home"]
            await pilot.press("u")  # home up, above spot
            await tui.until(lambda: [s.position for s in tab.program.steps]
                            == ["park", "home", "spot"], what="home moved up")
            assert tab._selected() == 2
            await pilot.press("delete")  # and deleted
            await tui.until(lambda: [s.position for s in tab.program.steps] == ["park", "spot"],
                            what="home deleted")
            await checked(tui, tab)
            assert tab.checked is not None, tab.problems

            # saved: the file reads back as the listing, carrying the taught position
            await pilot.press("w")
            await tui.until(path.exists, what="the program saved")
            saved = read_program(path)
            assert [(s.position, s.speed) for s in saved.steps] == [("park", 1.0), ("spot", 1.0)]
            assert np.allclose(saved.positions["spot"], start, atol=0.5)
            await tui.until(lambda: not tab.dirty)

            # opened again (l) and checked clean; one step; the rest to the end
            before = tab.program
            await pilot.press("l")
            await tui.until(lambda: tab.program is not before, what="the file opened again")
            assert tab.program.source == path and tab.program == saved
            await checked(tui, tab)
            assert tab.checked is not None and not tab.problems, tab.problems
            await pilot.press("n")
            await tui.until(lambda: tab.runner is not None and tab.runner.state
                            is RunnerState.HELD, RUN_S, what="one step done, held")
            assert [r.visit.step.number for r in tab.runner.results] == [1]
            # the next marked, once the tab has the step's report (the runner's thread is
            # held before the UI's queue reaches it: a loaded run read tab.at == 1)
            await tui.until(lambda: tab.at == 2, what=lambda: f"step 2 marked, not {tab.at}")
            assert "complete" in (await listed(tui, tab, pilot))[1]
            assert np.allclose(app.client.status().position, app.machine.park, atol=0.5)
            await pilot.press("r")
            await ended(tui, tab)
            outcome = tab.runner.outcome()
            assert outcome.complete, outcome.reason
            assert [(r.visit.step.number, r.status) for r in outcome.results] == [
                (1, "complete"), (2, "complete")]
            rows = (await listed(tui, tab, pilot))
            assert all("complete" in rows[n] and " s" in rows[n] for n in (1, 2)), rows
            assert np.allclose(app.client.status().position, start, atol=0.5)

            # a bad program: each problem with its line and step; r runs nothing
            await open_path(tui, tab, pilot, path.parent / "bad.toml")
            await checked(tui, tab)
            problems = tab.query_one("#program-problems").text
            assert "2 problem(s)" in problems, problems
            assert "line 5, step 1: no taught position 'nowhere'" in problems, problems
            assert "line 10, step 2:" in problems and "-27…30" in problems, problems
            await pilot.press("r")  # on a loaded machine Pilot's idle wait may come first
            await tui.until(lambda: "problem(s)" in said(tui, tab), what="r refused")
            assert tab.runner is None and not app.client.status().moving


            # the Runs tab: the program run's moves together, in its order, named by it
            await pilot.press("f6")
            runs = app.tab("runs")
            await tui.until(lambda: len(runs.infos) >= 2, what="the runs listed")
            cells = [str(row[-1]) for row in (runs.query_one("#runs-table", DataTable)
                                              .get_row_at(i) for i in range(len(runs.infos)))]
            mark = f"taught #{outcome.run_id[-4:]}"
            assert [c for c in cells if mark in c] == [f"{mark} · step 1", f"{mark} · step 2"]
            first = next(i for i, c in enumerate(cells) if mark in c)
            assert mark in cells[first + 1], cells  # together

    asyncio.run(scenario())


def test_hold_resume_stop_start_from_a_step_t1s_enabling_key_and_the_refusals(
        tui, data_dir: Path) -> None:
    async def scenario() -> None:
        app = tui.app()
        folder = data_dir / "programs"
        folder.mkdir(parents=True)
        (folder / "slow.toml").write_text(SLOW)
        (folder / "t1.toml").write_text(T1)
        (folder / "wait.toml").write_text('machine = "unimate2000b"\n\n[[step]]\n'
                                          'wait = "operator"\n')
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            client = app.client
            tab = await program_tab(tui, app, pilot)

            # held and resumed: the move stands on its path, then goes on; stopped: it holds
            await open_path(tui, tab, pilot, folder / "slow.toml")
            await checked(tui, tab)
            assert tab.checked is not None, tab.problems
            await pilot.press("r")
            await tui.until(lambda: client.status().moving and client.status().move_done > 200,
                            RUN_S, what="step 1 moving")
            await pilot.press("p")
            await tui.until(lambda: client.status().paused, what="the feed hold")
            assert tab.runner.state is RunnerState.PAUSED
            await pilot.press("p")
            await tui.until(lambda: not client.status().paused, what="resumed")
            assert tab.runner.state is RunnerState.RUNNING
            await pilot.press("s")
            await ended(tui, tab)
            assert tab.runner.state is RunnerState.STOPPED
            assert not client.status().moving
            assert "stopped by the" in (await listed(tui, tab, pilot))[1]

            # from step 2: asked first; no, then yes: only step 2 runs, from where the arm is
            table = tab.query_one("#program-table", DataTable)
            table.move_cursor(row=1)
            stopped = tab.runner
            await pilot.press("f")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            assert "Start from step 2" in app.screen.question
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, ConfirmScreen))
            assert tab.runner is stopped and "cancelled" in said(tui, tab)
            await pilot.press("f")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            await pilot.press("y")
            await tui.until(lambda: tab.runner is not stopped, what="a new program run")
            await ended(tui, tab)
            outcome = tab.runner.outcome()
            assert outcome.complete and [r.visit.step.number for r in outcome.results] == [2]

            # an operator's wait lasts until g
            await open_path(tui, tab, pilot, folder / "wait.toml")
            await checked(tui, tab)
            await pilot.press("g")  # nothing waits yet
            assert "no step waits for the operator" in said(tui, tab)
            await pilot.press("r")
            await tui.until(lambda: "g goes on" in said(tui, tab), what="the wait shown")
            assert tab.runner.state is RunnerState.RUNNING and not tab.runner.results
            await pilot.press("g")
            await ended(tui, tab)
            assert [(r.visit.step.number, r.status) for r in tab.runner.results] == [(1, "ok")]

            # reduced speed (T1): r is refused; the program goes only while space repeats
            await pilot.press("ctrl+y")  # reduced speed: at once
            await tui.until(lambda: client.speed_mode == "reduced", what="T1")
            await open_path(tui, tab, pilot, folder / "t1.toml")
            await checked(tui, tab)
            await pilot.press("r")  # refused: T1 runs on the enabling key
            await tui.until(lambda: "hold space" in said(tui, tab), what="r refused in T1")
            assert tab.runner is None

            async def hold_space(until, what: str) -> None:
                """Space repeating every REPEAT_S until ``until()``."""
                deadline = time.monotonic() + RUN_S
                while not until():
                    if time.monotonic() > deadline:
                        pytest.fail(f"timed out holding space for {what}")
                    tui.post_key(app, "space")
                    await asyncio.sleep(REPEAT_S)

            await hold_space(lambda: client.status().moving and client.status().move_done > 200,
                             "step 1 moving")
            assert tab.runner.state is RunnerState.RUNNING
            # let go: a feed hold, and the step goes no further while the key is up
            await tui.until(lambda: client.status().paused, what="the hold on release")
            assert tab.runner.state is RunnerState.PAUSED
            released = client.status().time_s
            standing: list[int] = []  # where the move is, a second and two seconds later

            def later(seconds: float) -> bool:
                status = client.status()
                if status.time_s < released + seconds:
                    return False
                standing.append(status.move_done)
                return True

            await tui.until(lambda: later(1.0), what="a second on the controller's clock")
            await tui.until(lambda: later(2.0), what="two seconds on the controller's clock")
            assert standing[0] == standing[1] and client.status().moving, standing
            assert tab.at == 1 and not tab.runner.results
            # held again: it goes on, step after step, to the end
            await hold_space(lambda: tab.runner.state.over, "the end")
            ended_run = tab.runner
            outcome = ended_run.outcome()
            assert outcome.complete, outcome.reason
            assert [r.visit.step.number for r in outcome.results] == [1, 2]
            assert client.speed_mode == "reduced"
            # held on past the end: the hold goes on, and starts nothing (its next repeat
            # was taken for a new press, and ran the program again)
            more = time.monotonic() + 0.5
            await hold_space(lambda: time.monotonic() > more, "half a second past the end")
            await tui.until(lambda: not tab.enabling.held, what="the release seen")
            assert tab.runner is ended_run and not client.status().moving
            # n in T1: nothing moves until space is held, and then one step only
            await pilot.press("n")  # waited for: Pilot's idle wait returns early under load
            await tui.until(lambda: "hold space to run one step" in said(tui, tab),
                            what=lambda: f"n in T1 waiting for space; it says {said(tui, tab)!r}")
            assert tab.runner is not None and tab.runner.state.over
            assert not client.status().moving
            await hold_space(lambda: tab.runner.state is RunnerState.HELD, "one step")
            assert [r.visit.step.number for r in tab.runner.results] == [1]

            # refused, with the reason: a move running elsewhere, then the E-stop latched
            here = np.array(client.status().position)
            plan = form_plans.go_to(app.machine, here, app.machine.park, 0.1, dt=client.dt)
            client.run(plan)
            await tui.until(lambda: client.status().moving, what="a move of the test's")
            runner = tab.runner
            await pilot.press("n")  # refused at once, before any enabling key
            await tui.until(lambda: "a move is running" in said(tui, tab),
                            what=lambda: f"n refused; it says {said(tui, tab)!r}")
            assert tab.runner is runner
            await pilot.press("ctrl+e")
            await tui.until(lambda: client.status().estop, what="the E-stop")
            await pilot.press("n")
            await tui.until(lambda: "the E-stop is latched" in said(tui, tab),
                            what=lambda: f"n refused; it says {said(tui, tab)!r}")
            assert tab.runner is runner

    asyncio.run(scenario())


def test_the_rig_example_runs_from_the_tab_and_an_unzeroed_rig_is_refused(tui) -> None:
    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            tab = await program_tab(tui, app, pilot)
            field = tab.query_one("#program-path", Input)
            example = EXAMPLES / "rig_sequence.toml"
            await tui.until(lambda: field.value == str(example), what="the example offered")
            # a program that moves the rig before its encoder is zeroed is refused
            unzeroed = tui.data_dir / "programs" / "step.toml"
            unzeroed.parent.mkdir(parents=True)
            unzeroed.write_text('machine = "rig"\n\n[[step]]\nmove = "step"\ntarget = 300.0\n')
            await open_path(tui, tab, pilot, unzeroed)
            await checked(tui, tab)
            await pilot.press("r")
            await tui.until(lambda: "the encoders are not zeroed" in said(tui, tab),
                            what="r refused, not zeroed")
            assert tab.runner is None
            # the example begins with Initialise: it runs
            await open_path(tui, tab, pilot, example)
            await checked(tui, tab)
            assert tab.checked is not None, tab.problems
            await pilot.press("r")
            await ended(tui, tab)
            outcome = tab.runner.outcome()
            assert outcome.complete, outcome.reason
            assert [r.visit.step.number for r in outcome.results] == list(range(1, 8))
            rows = (await listed(tui, tab, pilot))
            assert all("complete" in rows[n] for n in range(1, 8)), rows

    asyncio.run(scenario())


def test_an_observer_opens_only_the_data_directorys_programs_and_cannot_run_or_save(
        controller_service, tui) -> None:
    async def scenario() -> None:
        # observes: nobody took command; builds the tabs it shows alone, as tui.app's do
        app = PilotedApp.attached(controller_service.socket, build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            pilot = DriverPilot(app)
            await tui.ready(app, pilot)
            tab = await program_tab(tui, app, pilot)
            field = tab.query_one("#program-path", Input)
            await tui.until(lambda: field.value.endswith("unimate_pick_and_place.toml"),
                            what="the example offered")
            await pilot.press("l")  # outside the data directory: not for an observer to read
            assert "only a file inside the data directory" in said(tui, tab)
            assert tab.program is None
            path = controller_service.data_dir / "programs" / "slow.toml"
            path.parent.mkdir(parents=True)
            path.write_text(SLOW)
            await open_path(tui, tab, pilot, path)  # inside: shown, and checked
            await checked(tui, tab)
            assert tab.checked is not None, tab.problems
            for key in ("r", "n"):
                await pilot.press(key)
                assert "observing" in said(tui, tab) and "take it first" in said(tui, tab)
                assert tab.runner is None and not app.client.status().moving
            await pilot.press("w")
            assert "save a program" in said(tui, tab) and "observing" in said(tui, tab)

    asyncio.run(scenario())


PROGRAM = parse_program("""name = "edit"
machine = "unimate2000b"

[[step]]
go = "home"

[[step]]
repeat = 2

[[step.steps]]
go = "park"

[[step.steps]]
wait = 1.0
""", "edit.toml")


def test_edits_keep_the_listing_numbered_as_the_file_will_be() -> None:
    moved, at = move_step(PROGRAM, 4, -1)  # the wait above the go to park, in its repeat
    assert [s.title for s, _ in moved.listing()] == ["go to 'home'", "repeat 2 times",
                                                     "wait 1 s", "go to 'park'"]
    assert at == 3 and moved.step(3).line > moved.step(2).line
    with pytest.raises(ValueError, match="first of its block"):
        move_step(PROGRAM, 3, -1)
    inserted, at = insert_go_to(PROGRAM, 3, "spot", 0.7, (1300.0, 0.0, 0.0, 0.0, 90.0, 0.0))
    assert at == 4 and inserted.step(4) == GoTo(4, inserted.step(4).line, position="spot",
                                                speed=0.7)
    assert inserted.positions["spot"] == (1300.0, 0.0, 0.0, 0.0, 90.0, 0.0)
    deleted, at = delete_step(PROGRAM, 2)  # the repeat with its steps
    assert [s.title for s, _ in deleted.listing()] == ["go to 'home'"] and at == 1
    with pytest.raises(ValueError, match="steps"):  # a repeat left empty is no program
        delete_step(delete_step(PROGRAM, 4)[0], 3)


def test_a_program_runs_moves_are_listed_together_in_its_order() -> None:
    """Newest first, as the Runs tab lists runs, but a program run's moves together where its
    newest is, oldest first (another run made in between does not split them)."""
    infos = [RunInfo(RunFiles.at(Path("runs"), stem)) for stem in ("e", "d", "c", "b", "a")]
    programs = {"e": {"run_id": "20261127-0540-7044", "name": "pick", "step": 4, "visit": 2},
                "c": {"run_id": "20261127-0540-7044", "name": "pick", "step": 3, "visit": 1},
                "a": {"run_id": "20261127-0540-7044", "name": "pick", "step": 1, "visit": 0}}
    assert [i.files.stem for i in grouped(infos, programs)] == ["a", "c", "e", "d", "b"]
    assert program_cell(programs["c"]) == "pick #7044 · step 3"
    assert program_cell(None) == ""
